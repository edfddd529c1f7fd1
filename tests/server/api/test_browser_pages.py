"""The participant pages in Chromium against a served API (no worker needed): the self-hosted
API docs render with every request outside the service refused, and "My submissions" lists the
team's submissions, is reached from the navigation and downloads what the team may see.
Screenshots at desktop and phone width land in ``ARENA_SCREENSHOTS`` when it is set."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import zipfile
from pathlib import Path
from urllib.parse import urlparse

import pytest

from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import EvaluationRun, ScenarioResult, Submission, Track, utcnow
from server.status import RunStatus, SubmissionStatus
from tests.server.api.test_browser import CHROMIUM, CHROMIUM_ARGS
from tests.server.builders import make_team, queued_submission, seed_scored
from tests.server.live import api_server
from tests.server.service_stack import shared_dir
from tests.settings import env_only

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(
        not CHROMIUM.exists(), reason="needs Debian's chromium (apt-get install chromium)"
    ),
]
DESKTOP = {"width": 1280, "height": 900}
PHONE = {"width": 390, "height": 844}


@pytest.fixture
def served(tmp_path):
    root = shared_dir("arena-pages-")
    settings = env_only(
        storage={"data_dir": root / "data"}, suites={"hidden_suite_dir": root / "suite"}
    )
    (root / "data").mkdir()
    upgrade_database(settings.storage.resolved_database_url)
    db = Database(settings.storage.resolved_database_url)
    team_id, token = make_team(db, "pages-team")
    other_id, _ = make_team(db, "other-team")
    ids = [
        seed_scored(db, team_id, (0.25, 716.1, 0.5, 0.125), method_name="first try"),
        seed_scored(
            db,
            team_id,
            (0.0, 512.34, 0.25, 0.0625),
            method_name="second try",
            interval=(0.0, 0.05),
        ),
        queued_submission(db, team_id),
    ]
    seed_scored(db, other_id, (0.1, 600.0, 0.2, 0.1), method_name="not ours", interval=(0.02, 0.2))
    db.dispose()
    with api_server(settings, tmp_path / "api.log") as (url, _):
        yield url, token, ids
    shutil.rmtree(root, ignore_errors=True)


def shoot(page, name: str) -> None:
    folder = os.environ.get("ARENA_SCREENSHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(folder) / f"{name}.png"), full_page=True)


@pytest.fixture
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield browser
        browser.close()


def offline_page(browser, url: str, viewport: dict):
    """A page that may reach the service only: every other request is refused and noted."""
    page = browser.new_page(viewport=viewport, accept_downloads=True)
    page.refused = []
    origin = urlparse(url).netloc

    def only_the_service(route):
        if urlparse(route.request.url).netloc == origin:
            route.continue_()
        else:
            page.refused.append(route.request.url)
            route.abort()

    page.route("**/*", only_the_service)
    return page


def test_api_docs_render_offline_with_a_favicon(served, browser):
    from playwright.sync_api import expect

    url, _, _ = served
    for name, viewport in (("docs-desktop", DESKTOP), ("docs-phone", PHONE)):
        page = offline_page(browser, url, viewport)
        page.goto(f"{url}/docs")
        expect(
            page.locator(".opblock-summary-path", has_text="/api/v1/submissions").first
        ).to_be_visible(timeout=15000)
        assert page.locator(".opblock").count() >= 8
        expect(page.locator("a[href='/guide/agent-interface']").first).to_be_visible()
        assert page.refused == []
        shoot(page, name)
        page.close()
    page = offline_page(browser, url, DESKTOP)
    favicon = page.request.get(f"{url}/favicon.ico")
    assert favicon.ok and favicon.headers["content-type"] == "image/png"
    assert page.request.get(f"{url}/redoc").status == 404  # ReDoc would fetch from a CDN


def test_agent_interface_guide_is_linked_from_submit(served, browser):
    from playwright.sync_api import expect

    url, _, _ = served
    for name, viewport in (("guide-desktop", DESKTOP), ("guide-phone", PHONE)):
        page = offline_page(browser, url, viewport)
        page.goto(f"{url}/submit")
        shoot(page, name.replace("guide", "submit"))
        page.click("main a[href='/guide/agent-interface']")
        expect(page.locator("h2", has_text="Action spaces")).to_be_visible()
        expect(page.locator("td code", has_text="LaneWithContinuousSpeed").first).to_be_visible()
        shoot(page, name)
        page.close()


def test_my_submissions_lists_the_team_and_downloads_results(served, browser, tmp_path):
    from playwright.sync_api import expect

    url, token, ids = served
    page = offline_page(browser, url, DESKTOP)
    page.goto(f"{url}/")
    expect(page.locator("#nav-mine")).to_be_hidden()
    page.goto(f"{url}/my-submissions")
    page.fill("#token", token)
    page.click("#token-form button")
    rows = page.locator("#mine tbody tr")
    expect(rows).to_have_count(3)
    # Newest first, only this team's, with status, track, formatted scores and a link.
    assert [int(r) for r in rows.evaluate_all("rs => rs.map(r => r.dataset.id)")] == ids[::-1]
    expect(page.locator("#mine")).not_to_contain_text("not ours")
    first = rows.nth(2)
    expect(first).to_contain_text("first try")
    expect(first).to_contain_text("scored")
    expect(first).to_contain_text("freestyle")
    expect(first).to_contain_text("716.1")
    expect(first).to_contain_text("0.2500")
    expect(rows.nth(0)).to_contain_text("queued")
    shoot(page, "mine-desktop")
    # The navigation now leads here from any page.
    page.goto(f"{url}/")
    page.click("#nav-mine")
    expect(page).to_have_url(f"{url}/my-submissions")
    expect(rows).to_have_count(3)
    with page.expect_download() as info:
        rows.nth(2).locator("a.download").click()
    saved = tmp_path / "download.zip"
    info.value.save_as(saved)
    with zipfile.ZipFile(io.BytesIO(saved.read_bytes())) as archive:
        # A final-phase submission: scores and counts, none of the agent's output.
        assert archive.namelist() == ["submission.json"]
        detail = json.loads(archive.read("submission.json"))
    assert detail["id"] == ids[0] and detail["metrics"]["time"] == pytest.approx(716.1)
    rows.nth(2).locator("td a").first.click()
    expect(page).to_have_url(f"{url}/submissions/{ids[0]}")
    assert page.refused == []
    page.close()
    phone = offline_page(browser, url, PHONE)
    phone.goto(f"{url}/my-submissions")
    phone.evaluate(f"sessionStorage.setItem('arena-token', {json.dumps(token)})")
    phone.reload()
    expect(phone.locator("#mine tbody tr")).to_have_count(3)
    # Nothing spills sideways off a phone screen: wide tables scroll inside their box.
    assert phone.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]
    shoot(phone, "mine-phone")


TRACEBACK = "Traceback (most recent call last):\nModuleNotFoundError: No module named 'torch'"


def add_results(db, submission_id: int, rows: list[tuple[str, str, str, str]]) -> None:
    """(family, status, reason, log tail) results on the submission's latest run."""
    with db.session() as session:
        run = session.get(Submission, submission_id).runs[-1]
        for k, (family, status, reason, log) in enumerate(rows):
            session.add(
                ScenarioResult(
                    run_id=run.id,
                    scenario_id=f"h{k:03d}",
                    family=family,
                    status=status,
                    reason=reason,
                    log_tail=log,
                )
            )


def running_submission(db, team_id: int, total: int) -> int:
    with db.session() as session:
        submission = Submission(
            team_id=team_id,
            phase="validation",  # where the team sees its agent's output
            track=Track.freestyle,
            method_name="in progress",
            file_sha256="0" * 64,
            file_size=1,
            upload_key="submissions/none/upload.zip",
            status=SubmissionStatus.running,
            started_at=utcnow(),
        )
        session.add(submission)
        session.flush()
        session.add(
            EvaluationRun(
                submission_id=submission.id,
                attempt=1,
                status=RunStatus.running,
                suite_dir="/nonexistent",
                manifest_sha256="0" * 64,
                episode_count=total,
                scoring_profile="driving-smarts-2022",
            )
        )
        return submission.id


def test_submission_page_groups_identical_output_and_hides_empty_sections(tmp_path, browser):
    from playwright.sync_api import expect

    root = shared_dir("arena-pages-")
    settings = env_only(
        storage={"data_dir": root / "data"}, suites={"hidden_suite_dir": root / "suite"}
    )
    (root / "data").mkdir()
    upgrade_database(settings.storage.resolved_database_url)
    db = Database(settings.storage.resolved_database_url)
    team_id, token = make_team(db, "logs-team")
    failed = seed_scored(
        db,
        team_id,
        (1.0, 800.0, None, None),
        method_name="import torch",
        phase="validation",
        interval=(1.0, 1.0),
    )
    add_results(db, failed, [("cruise", "done", "agent_error", TRACEBACK)] * 5)
    running = running_submission(db, team_id, total=10)
    add_results(db, running, [("cruise", "done", "reached_goal", "")] * 3)
    try:
        with api_server(settings, tmp_path / "api.log") as (url, _):
            for name, viewport in (("submission-desktop", DESKTOP), ("submission-phone", PHONE)):
                page = offline_page(browser, url, viewport)
                page.goto(f"{url}/my-submissions")
                page.evaluate(f"sessionStorage.setItem('arena-token', {json.dumps(token)})")
                page.goto(f"{url}/submissions/{failed}")
                expect(page.locator("#status")).to_have_text("scored")
                page.click("#logs-box summary")
                # Five identical tracebacks: one block, with its count.
                expect(page.locator("#logs pre")).to_have_count(1)
                expect(page.locator("#logs h3")).to_contain_text("× 5")
                expect(page.locator("#metric-humanness")).to_have_text("—")
                expect(page.locator("#metric-completion")).to_have_text("1.0000")
                expect(page.locator("#completion-interval")).to_have_text("[1.0000, 1.0000]")
                expect(page.locator("#failures")).to_contain_text("agent_error × 5")
                shoot(page, name)
                page.goto(f"{url}/submissions/{running}")
                expect(page.locator("#progress-text")).to_contain_text("3 / 10 scenarios")
                expect(page.locator("#progress-text")).to_contain_text("estimating time left")
                # Running, nothing per family yet and no failure counted: no empty headings.
                expect(page.locator("h2", has_text="Per family")).to_be_hidden()
                expect(page.locator("h2", has_text="Failures")).to_be_hidden()
                shoot(page, name.replace("submission", "running"))
                assert page.refused == []
                page.close()
    finally:
        db.dispose()
        shutil.rmtree(root, ignore_errors=True)


def test_leaderboard_fits_a_phone_and_formats_numbers_alike(served, browser):
    from playwright.sync_api import expect

    url, _, _ = served
    for name, viewport in (("leaderboard-desktop", DESKTOP), ("leaderboard-phone", PHONE)):
        page = offline_page(browser, url, viewport)
        page.goto(f"{url}/")
        expect(page.locator("tr.entry")).to_have_count(2)  # best per team
        expect(page.locator("#nav-mine")).to_be_hidden()  # no token in this tab
        expect(page.locator("tr.entry").first).to_contain_text("512.3")
        # Completion with its interval. Overlapping intervals alone tie nobody: "tied" is the
        # rank ranges' word, and scores kept without per-episode values are never compared.
        expect(page.locator("tr.entry").first).to_contain_text("[0.0000, 0.0500]")
        expect(page.locator("tr.entry .tied")).to_have_count(0)
        expect(page.locator("tr.entry .rank-range").first).to_have_attribute(
            "title", re.compile("not compared")
        )
        expect(page.locator("#interval-legend")).to_be_visible()
        assert page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
        shoot(page, name)
        page.close()


def test_submission_page_over_training_seeds_counts_every_seeds_failures(
    settings, db, browser, tmp_path
):
    """Failure counts summed over the seeds (labelled so) and each seed's, and the manifest's
    model digest per seed."""
    from playwright.sync_api import expect

    from tests.server.services.test_training_seeds import claim, evaluate, set_seeds, start, trained

    set_seeds(db, settings, 2)
    team_id, token = make_team(db, "seeds-team")
    sid = queued_submission(db, team_id, track=Track.offline)
    for training_id, fails in zip(start(db, settings, sid), (1, 2), strict=True):
        evaluate(db, settings, trained(db, settings, claim(db, settings, training_id)), fails)
    with api_server(settings, tmp_path / "api.log") as (url, _):
        page = offline_page(browser, url, DESKTOP)
        page.goto(f"{url}/my-submissions")
        page.evaluate(f"sessionStorage.setItem('arena-token', {json.dumps(token)})")
        page.goto(f"{url}/submissions/{sid}")
        expect(page.locator("#status")).to_have_text("scored")
        expect(page.locator("#failures-scope")).to_have_text(
            "(episodes summed over the 2 training seeds; each seed's below)"
        )
        expect(page.locator("#failures .per-seed > li")).to_have_count(2)
        expect(page.locator("#failures .per-seed > li").nth(1)).to_contain_text("seed 1:")
        # The progress and the agent's CPU are the whole set's, not one seed's run.
        episodes = int(page.locator("#progress-text").inner_text().split(" / ")[0])
        expect(page.locator("#progress-text")).to_have_text(
            f"{episodes} / {episodes} scenarios over 2 training seeds"
        )
        assert episodes % 2 == 0
        expect(page.locator("#agent-cpu")).to_contain_text("used over the 2 seeds' evaluations")
        expect(page.locator("#failures .per-seed > li").nth(1)).to_contain_text("collision × 2")
        page.click("#manifest-box summary")
        expect(page.locator("#manifest")).to_contain_text("trained model sha256, seed 0")
        expect(page.locator("#manifest")).to_contain_text("trained model sha256, seed 1")
        expect(page.locator("#manifest")).to_contain_text("agent's stack")
        shoot(page, "submission-seeds")
        assert page.refused == []
        page.close()
