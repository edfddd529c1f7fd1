"""Every page at phone width (390 px) in Chromium: no horizontal page scroll (wide tables scroll
in their own box), screenshots at phone and desktop width in ``ARENA_SCREENSHOTS`` when set.
And what a team must always see on them: the phase (dates, what a hidden phase hides, up front),
timings, rank and interval, uploads left today, a training submission said as training."""

from __future__ import annotations

import json
import os
import shutil
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from arena.suite import SHIPPED_PUBLIC_DIR, load_suite
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import Phase, Submission, TrainingJob, Visibility, utcnow
from server.status import SubmissionStatus, TrainingStatus
from server.tracks import Track
from tests.evaluator.scoring.builders import simulated
from tests.server.api.test_browser import CHROMIUM
from tests.server.api.test_browser_pages import (
    DESKTOP,
    PHONE,
    TRACEBACK,
    add_results,
    browser,  # noqa: F401 (fixture)
    offline_page,
    running_submission,
    shoot,
)
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
ADMIN = "admin-token-for-the-phone-pages"
SITE_KEYS = (
    "final", "validation", "running", "training", "queued", "failed_training", "scenario"
)  # fmt: skip
FAMILIES = {
    name: {"scenarios": 9, "completion": 0.25, "time": 716.1, "humanness": 0.5, "rules": 0.125}
    for name in ("cruise", "cut_in", "left_turn_t", "merge", "overtake", "naturalistic_replay")
}


def training_submission(db, team_id: int) -> int:
    with db.session() as session:
        submission = Submission(
            team_id=team_id,
            phase="validation",
            track=Track.offline,
            method_name="offline learner",
            file_sha256="0" * 64,
            file_size=1,
            upload_key="submissions/none/upload.zip",
            status=SubmissionStatus.training,
            queued_at=utcnow() - timedelta(minutes=3),
            started_at=utcnow() - timedelta(minutes=2),
        )
        session.add(submission)
        session.flush()
        session.add(
            TrainingJob(
                submission_id=submission.id,
                attempt=1,
                status=TrainingStatus.training,
                elapsed_s=95.0,
                log_tail="epoch 3/10 loss 0.41\n",
            )
        )
        return submission.id


def publish_curves(settings, db, submission_id: int, output) -> None:
    """Curves as the worker publishes them while the submission's train.py runs."""
    from evaluator.training.metrics import METRICS_FILE
    from server.core.artifacts import artifact_store
    from server.services.training_curves import CurvePublisher

    with db.read_session() as session:
        job = session.scalar(
            select(TrainingJob.id).where(TrainingJob.submission_id == submission_id)
        )
    output.mkdir()
    (output / METRICS_FILE).write_text(
        "".join(
            f"{epoch},loss,{0.9 * 0.93**epoch + 0.02 * (epoch % 3):.4f}\n"
            f"{epoch},val_loss,{0.95 * 0.95**epoch + 0.03:.4f}\n"
            for epoch in range(1, 41)
        )
    )
    CurvePublisher(artifact_store(settings.storage, db), job, output).publish()


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A served API with one team's submissions in every state and phase, a closed phase and a
    phase that opens later."""
    root = shared_dir("arena-phone-")
    settings = env_only(
        storage={"data_dir": root / "data"},
        suites={"hidden_suite_dir": SHIPPED_PUBLIC_DIR},
        service={"admin_token": ADMIN},
    )
    (root / "data").mkdir()
    upgrade_database(settings.storage.resolved_database_url)
    db = Database(settings.storage.resolved_database_url)
    with db.session() as session:
        session.add(
            Phase(
                name="warmup",
                suite="public",
                visibility=Visibility.full,
                starts_at=utcnow() - timedelta(days=20),
                ends_at=utcnow() - timedelta(days=10),
            )
        )
        session.add(
            Phase(
                name="bonus-round-with-a-long-name",
                suite="public",
                visibility=Visibility.hidden,
                starts_at=utcnow() + timedelta(days=10),
            )
        )
    # Per-episode values of two agents the suite cannot tell apart: their ranks are a range.
    rng = np.random.default_rng(3)
    team_id, token = make_team(db, "a-team-with-a-rather-long-name-for-a-phone")
    other_id, _ = make_team(db, "other")
    final = seed_scored(
        db,
        team_id,
        (0.25, 716.1, 0.5, 0.125),
        method_name="a method with a long descriptive name, version 12",
        interval=(0.1, 0.4),
        families=FAMILIES,
        samples=simulated(rng, 0.2, scenarios=24),
    )
    seed_scored(
        db,
        other_id,
        (0.1, 600.0, 0.2, 0.1),
        interval=(0.02, 0.2),
        families=FAMILIES,
        samples=simulated(rng, 0.2, scenarios=24),
    )
    validation = seed_scored(
        db,
        team_id,
        (1.0, 800.0, None, None),
        phase="validation",
        interval=(1.0, 1.0),
        families=FAMILIES,
    )
    scenario = load_suite(SHIPPED_PUBLIC_DIR).scenarios[0].id
    add_results(db, validation, [("cruise", "done", "agent_error", TRACEBACK)] * 3)
    running = running_submission(db, team_id, total=10)
    training = training_submission(db, team_id)
    publish_curves(settings, db, training, root / "curves")
    queued = queued_submission(db, team_id)
    failed_training = training_submission(db, team_id)
    with db.session() as session:
        session.get(Submission, failed_training).status = SubmissionStatus.failed
        session.get(Submission, failed_training).status_reason = "train_error: train.py exited 1"
        job = session.scalar(
            select(TrainingJob).where(TrainingJob.submission_id == failed_training)
        )
        job.status, job.failure, job.error = TrainingStatus.failed, "train_error", "exited 1"
    db.dispose()
    log = tmp_path_factory.mktemp("phone") / "api.log"
    with api_server(settings, log) as (url, _):
        yield {
            "url": url,
            "token": token,
            "final": final,
            "validation": validation,
            "running": running,
            "training": training,
            "queued": queued,
            "failed_training": failed_training,
            "scenario": scenario,
        }
    shutil.rmtree(root, ignore_errors=True)


def pages(site) -> dict[str, str]:
    """Every page of the site (name -> path)."""
    scenario = site["scenario"]
    return {
        "leaderboard": "/",
        "leaderboard-validation": "/?phase=validation",
        "submit": "/submit",
        "scenarios": "/scenarios",
        "scenario-replay": f"/scenarios/{scenario}/replay",
        "mine": "/my-submissions",
        "submission-final": f"/submissions/{site['final']}",
        "submission-validation": f"/submissions/{site['validation']}",
        "submission-running": f"/submissions/{site['running']}",
        "submission-training": f"/submissions/{site['training']}",
        "submission-queued": f"/submissions/{site['queued']}",
        "submission-replay": f"/submissions/{site['validation']}/replays/h000",
        "admin-replay": f"/admin/submissions/{site['final']}/replays/{scenario}",
        "guide-agent-interface": "/guide/agent-interface",
        "guide-submissions": "/guide/submissions",
        "guide-scoring": "/guide/scoring",
        "docs": "/docs",
    }


def open_page(browser, site, path: str, viewport: dict):  # noqa: F811 (fixture name)
    page = offline_page(browser, site["url"], viewport)
    page.goto(f"{site['url']}/my-submissions")
    page.evaluate(f"sessionStorage.setItem('arena-token', {json.dumps(site['token'])})")
    page.evaluate(f"sessionStorage.setItem('arena-admin-token', {json.dumps(ADMIN)})")
    page.goto(f"{site['url']}{path}")
    page.wait_for_load_state("networkidle")
    page.wait_for_timeout(300)  # the pages render what they fetched
    return page


# The page names, for the test ids (the paths need the served site's ids).
PAGE_NAMES = list(pages(dict.fromkeys(SITE_KEYS, 0)))


@pytest.mark.parametrize("name", PAGE_NAMES)
def test_no_page_scrolls_sideways_on_a_phone(site, browser, name):  # noqa: F811
    path = pages(site)[name]
    for label, viewport in (("phone", PHONE), ("desktop", DESKTOP)):
        page = open_page(browser, site, path, viewport)
        width = page.evaluate("document.documentElement.scrollWidth")
        inner = page.evaluate("window.innerWidth")
        shoot(page, f"{name}-{label}")
        assert width <= inner, f"{path} at {label} width: {width} px wide in {inner} px"
        assert page.refused == []
        page.close()


def test_a_team_sees_phase_timings_rank_and_what_is_hidden(site, browser):  # noqa: F811
    from playwright.sync_api import expect

    page = open_page(browser, site, f"/submissions/{site['final']}", PHONE)
    expect(page.locator("#phase-name")).to_have_text("final")
    # Up front, not inside an expander: what the hidden phase hides and why.
    hidden = page.locator("#phase-hidden")
    expect(hidden).to_be_visible()
    expect(hidden).to_contain_text("secret scenario suite")
    assert hidden.evaluate("e => e.closest('details') === null")
    expect(page.locator("#standing")).to_contain_text("rank 2 of 2")
    expect(page.locator("#standing")).to_contain_text("left today")
    expect(page.locator("#completion-interval")).to_have_text("[0.1000, 0.4000]")
    expect(page.locator("#timings")).to_contain_text("started")
    expect(page.locator("#timings")).not_to_contain_text("running for")  # it is scored
    page.goto(f"{site['url']}/submissions/{site['training']}")
    expect(page.locator("#progress-text")).to_contain_text("training")
    expect(page.locator("#progress-text")).not_to_contain_text("0 / 0")
    page.goto(f"{site['url']}/my-submissions")
    rows = page.locator("#mine tbody tr")
    expect(rows).to_have_count(6)
    expect(page.locator("#mine thead")).to_contain_text("Phase")
    expect(rows.last).to_contain_text("final")
    page.close()


def test_the_submit_form_says_every_phase_its_dates_and_tries_left(site, browser):  # noqa: F811
    from playwright.sync_api import expect

    page = open_page(browser, site, "/submit", PHONE)
    options = page.locator("#phase option")
    texts = options.all_inner_texts()
    assert "warmup" in texts and "bonus-round-with-a-long-name" in texts
    closed = page.locator("#phase option[value='warmup']")
    assert closed.get_attribute("disabled") is not None
    # Every option fits the phone's select (a long phase name once ran past its edge); the
    # chosen phase in full below it, the others' dates beside.
    fits = page.evaluate(
        """() => {
          const select = document.getElementById("phase");
          const style = getComputedStyle(select);
          const context = document.createElement("canvas").getContext("2d");
          context.font = `${style.fontWeight} ${style.fontSize} ${style.fontFamily}`;
          const room = select.clientWidth - 40;  // the padding and the arrow
          return [...select.options].map((o) => context.measureText(o.text).width <= room);
        }"""
    )
    assert all(fits), (texts, fits)
    expect(page.locator("#other-phases")).to_contain_text("bonus-round-with-a-long-name opens")
    expect(page.locator("#other-phases")).to_contain_text("warmup closed")
    expect(page.locator("#phase-detail")).to_contain_text("Phase final: hidden suite")
    page.select_option("#phase", "validation")
    expect(page.locator("#phase-detail")).to_contain_text("Phase validation: public scenarios")
    expect(page.locator("#tries-left")).to_contain_text("left today")
    page.close()


def test_a_refused_upload_shows_the_message_without_a_raw_status(site, browser, tmp_path):  # noqa: F811
    from playwright.sync_api import expect

    bad = tmp_path / "not-a-zip.zip"
    bad.write_bytes(b"this is not a zip")
    page = open_page(browser, site, "/submit", DESKTOP)
    page.fill("#token", site["token"])
    page.fill("#method_name", "m")
    page.set_input_files("#file", str(bad))
    page.click("#submit-button")
    expect(page.locator("#submit-error")).to_be_visible()
    assert "422" not in page.locator("#submit-status").inner_text()
    assert "Rejected" not in page.locator("#submit-status").inner_text()
    page.close()


def test_an_organiser_watches_a_hidden_phase_episode(site, browser):  # noqa: F811
    from playwright.sync_api import expect

    path = f"/admin/submissions/{site['final']}/replays/{site['scenario']}"
    page = offline_page(browser, site["url"], DESKTOP)
    page.goto(f"{site['url']}{path}")
    expect(page.locator("#token-form")).to_be_visible()
    expect(page.locator("#token-form label")).to_contain_text("Admin token")
    page.fill("#token", "wrong")
    page.click("#token-form button")
    expect(page.locator("#replay")).to_contain_text("admin token required")
    # With the admin token the admin API answers for a hidden-phase submission (a team's
    # token gets 403 there): here it has no recorded episode to show.
    page.evaluate(f"sessionStorage.setItem('arena-admin-token', {json.dumps(ADMIN)})")
    page.reload()
    expect(page.locator("#replay")).to_contain_text("has no recorded episode")
    page.close()


# `ARENA_DOC_IMAGES=1`: the charts' screenshots are written where docs/ shows them.
DOC_IMAGES = Path(__file__).parents[3] / "docs" / "images"


def test_results_and_rank_ranges_are_drawn_at_desktop_and_phone_width(site, browser):  # noqa: F811
    from playwright.sync_api import expect

    for label, viewport in (("1280", DESKTOP), ("390", PHONE)):
        page = open_page(browser, site, f"/submissions/{site['final']}", viewport)
        chart = page.locator("#results-chart svg")
        expect(chart).to_be_visible()
        # Every family's four metrics beside the leaderboard median, the interval as a bar.
        assert chart.locator("rect.bar").count() == len(FAMILIES) * 4
        assert chart.locator("line.median").count() == len(FAMILIES) * 4
        expect(chart.locator("g.interval rect.range")).to_have_count(1)
        expect(chart).to_contain_text("[0.1000, 0.4000]")
        assert chart.bounding_box()["width"] <= viewport["width"]
        if os.environ.get("ARENA_DOC_IMAGES"):
            chart.screenshot(path=DOC_IMAGES / f"results-chart-{label}.png")
        board = open_page(browser, site, "/", viewport)
        ranks = board.locator("#leaderboard svg.rank-chart")
        expect(ranks).to_have_count(2)
        # Both could rank 1 to 2: tied, the range drawn and the chance to be ahead shown.
        expect(board.locator("#leaderboard .tied")).to_have_count(2)
        expect(board.locator("td.ahead").first).to_contain_text("%")
        expect(ranks.first).to_be_visible()  # drawn in the rank cell, not behind a hover
        if os.environ.get("ARENA_DOC_IMAGES"):
            board.locator("#leaderboard").screenshot(path=DOC_IMAGES / f"leaderboard-{label}.png")
        page.close()
        board.close()


def test_a_hidden_phase_page_asks_for_nothing_it_may_not_see(site, browser):  # noqa: F811
    """Two 403s from /logs once reached the console of a hidden phase's submission page, and
    its notice showed `literal backticks`."""
    from playwright.sync_api import expect

    page = offline_page(browser, site["url"], PHONE)
    asked: list[str] = []
    page.on("request", lambda request: asked.append(request.url))
    page.goto(f"{site['url']}/my-submissions")
    page.evaluate(f"sessionStorage.setItem('arena-token', {json.dumps(site['token'])})")
    page.goto(f"{site['url']}/submissions/{site['final']}")
    page.wait_for_load_state("networkidle")
    notice = page.locator("#phase-hidden")
    expect(notice).to_contain_text("arena evaluate")
    assert "`" not in notice.inner_text()
    expect(notice.locator("code")).to_have_text("arena evaluate")
    assert not [url for url in asked if url.endswith("/logs")]
    page.close()


def test_training_curves_are_drawn_while_it_trains(site, browser):  # noqa: F811
    from playwright.sync_api import expect

    for label, viewport in (("1280", DESKTOP), ("390", PHONE)):
        page = open_page(browser, site, f"/submissions/{site['training']}", viewport)
        curves = page.locator("#training-curves svg")
        expect(curves).to_be_visible()
        expect(curves).to_contain_text("training: updated as train.py writes")
        expect(curves.locator("polyline")).to_have_count(2)  # loss and val_loss
        assert curves.bounding_box()["width"] <= viewport["width"]
        if os.environ.get("ARENA_DOC_IMAGES"):
            curves.screenshot(path=DOC_IMAGES / f"training-curves-{label}.png")
        page.close()


def test_a_submission_that_failed_in_training_lists_no_failures(site, browser):  # noqa: F811
    """It once said "Failures: None." under a submission whose train.py failed: no episode ran."""
    from playwright.sync_api import expect

    page = open_page(browser, site, f"/submissions/{site['failed_training']}", PHONE)
    expect(page.locator("#status")).to_have_text("failed")
    expect(page.locator("#training-text")).to_contain_text("train_error")
    expect(page.locator("#failures-box")).to_be_hidden()
    page.goto(f"{site['url']}/submissions/{site['validation']}")  # ran episodes: counted
    expect(page.locator("#failures-box")).to_be_visible()
    page.close()


def test_the_browser_rounds_every_figure_as_the_server_does(site, browser):  # noqa: F811
    """The submission page writes figures with toFixed (app.js fmt), the server with
    arena/figures.py: one rule, halves away from zero (0.53125 once read 0.5313 on the page and
    0.5312 on the leaderboard). Checked on every fraction of a 128- and a 384-scenario suite."""
    from arena.figures import metric_text

    values = sorted({k / n for n in (128, 384, 256 * 3) for k in range(n + 1)})
    page = open_page(browser, site, "/", PHONE)
    shown = page.evaluate("values => values.map((v) => v.toFixed(4))", values)
    times = [v * 800 for v in values]
    shown_times = page.evaluate("values => values.map((v) => v.toFixed(1))", times)
    page.close()
    assert shown == [metric_text("completion", v) for v in values]
    assert shown_times == [metric_text("time", v) for v in times]
