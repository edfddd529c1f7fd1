"""The web pages in a real browser (Playwright driving Debian's Chromium) against the embedded
service (SQLite, SQLAlchemy broker): upload an example agent through the form, watch it get
scored on its submission page, find it on the leaderboard."""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import pytest
from sqlalchemy import select

from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import ScenarioResult
from tests.server.builders import make_team, pack_example
from tests.server.live import api_server, stop
from tests.server.service_stack import SCENARIOS, build_small_suite, shared_dir, start_worker
from tests.settings import env_only, with_fields

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.bwrap,
    pytest.mark.browser,
    pytest.mark.skipif(
        not CHROMIUM.exists(), reason="needs Debian's chromium (apt-get install chromium)"
    ),
]


@pytest.fixture
def embedded_settings():
    root = shared_dir("arena-browser-")
    data = root / "data"
    data.mkdir()
    settings = env_only(
        storage={"data_dir": data},
        suites={"hidden_suite_dir": build_small_suite(root)},
        sandbox={"kind": "bubblewrap"},
        service={"lease_seconds": 30, "reaper_interval_s": 5},
    )
    upgrade_database(settings.storage.resolved_database_url)
    yield settings
    shutil.rmtree(root, ignore_errors=True)


def test_upload_through_the_form_and_read_the_result(embedded_settings, tmp_path):
    from playwright.sync_api import expect, sync_playwright

    db = Database(embedded_settings.storage.resolved_database_url)
    _, token = make_team(db, "browser-team")
    db.dispose()
    bad_zip = tmp_path / "bad.zip"
    bad_zip.write_bytes(b"not a zip at all")
    no_policy_zip = tmp_path / "no-policy.zip"
    with zipfile.ZipFile(no_policy_zip, "w") as archive:
        archive.writestr("agent.yaml", "action_space: TargetPose\n")
    agent_zip = pack_example("keep_lane", tmp_path)
    worker = start_worker(embedded_settings, tmp_path / "worker.log")
    try:
        with (
            api_server(embedded_settings, tmp_path / "api.log") as (url, _),
            sync_playwright() as playwright,
        ):
            browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            page = browser.new_page()
            page.goto(f"{url}/submit")
            page.fill("#token", token)
            page.select_option("#track", "freestyle")
            page.fill("#method_name", "lane keeper")
            page.fill("#description", "stays in its lane")
            # A broken zip: the intake's message is shown and nothing is submitted.
            page.set_input_files("#file", str(bad_zip))
            page.click("#submit-button")
            expect(page.locator("#submit-error")).to_contain_text("rule:", timeout=30_000)
            assert page.url.endswith("/submit")
            # A zip only its validation can judge: validating, then its rule, on the form.
            page.set_input_files("#file", str(no_policy_zip))
            page.click("#submit-button")
            expect(page.locator("#submit-status")).to_contain_text("validating")
            expect(page.locator("#submit-error")).to_contain_text("policy-missing", timeout=60_000)
            assert page.url.endswith("/submit")

            page.set_input_files("#file", str(agent_zip))
            page.click("#submit-button")
            page.wait_for_url("**/submissions/*", timeout=60_000)
            expect(page.locator("#status")).to_have_text("scored", timeout=180_000)
            expect(page.locator("#progress-text")).to_have_text(
                f"{len(SCENARIOS)} / {len(SCENARIOS)} scenarios"
            )
            completion = float(page.locator("#metric-completion").inner_text())
            assert 0.0 <= completion <= 1.0
            # The results drawn by the server: a bar per metric and family.
            expect(page.locator("#results-chart svg rect.bar").first).to_be_attached()
            # The CPU the worker measured, against the evaluation's budget and the phase's limits.
            expect(page.locator("#agent-cpu")).to_contain_text(
                "used of this evaluation's budget of 18 h 0 min"
            )
            expect(page.locator("#phase-dates")).to_contain_text(
                "Agent CPU limits: 1 s per act, 600 s per episode, 64800 s per evaluation."
            )

            page.goto(f"{url}/?track=freestyle")
            row = page.locator("#leaderboard tr.entry").first
            expect(row.locator(".method")).to_have_text("lane keeper", timeout=10_000)
            expect(row.locator(".team")).to_have_text("browser-team")
            assert float(row.locator(".completion").inner_text()) == pytest.approx(completion)
            browser.close()
    finally:
        stop(worker)
    # Every episode's agent CPU was measured in the worker's sandbox and stored.
    db = Database(embedded_settings.storage.resolved_database_url)
    with db.read_session() as session:
        used = session.scalars(select(ScenarioResult.agent_cpu_s)).all()
    db.dispose()
    assert len(used) == len(SCENARIOS) and all(seconds > 0 for seconds in used), used


def test_an_offline_submission_through_the_form_trains_then_ranks(embedded_settings, tmp_path):
    """The Track 2 path a new user takes: the example offline submission uploaded with the
    form, its training shown on its page, then its score, then the offline leaderboard."""
    from playwright.sync_api import expect, sync_playwright

    from arena.suite import SHIPPED_PUBLIC_DIR
    from scenarios.dataset.build import TRANSITIONS, write_transitions
    from scenarios.dataset.collect import collect

    dataset = embedded_settings.storage.data_dir.parent / "dataset"
    dataset.mkdir()
    write_transitions(dataset / TRANSITIONS, collect(SHIPPED_PUBLIC_DIR / "p030_replay_cruise")[0])
    (dataset / TRANSITIONS).chmod(0o644)
    settings = with_fields(embedded_settings, training={"train_dataset_dir": dataset})
    db = Database(settings.storage.resolved_database_url)
    _, token = make_team(db, "offline-team")
    db.dispose()
    agent_zip = pack_example("offline_bc", tmp_path)
    worker = start_worker(settings, tmp_path / "worker.log")
    try:
        with (
            api_server(settings, tmp_path / "api.log") as (url, _),
            sync_playwright() as playwright,
        ):
            browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            page = browser.new_page()
            page.goto(f"{url}/submit")
            page.fill("#token", token)
            page.select_option("#track", "offline")
            page.fill("#method_name", "behaviour cloning")
            page.set_input_files("#file", str(agent_zip))
            page.click("#submit-button")
            page.wait_for_url("**/submissions/*", timeout=60_000)
            expect(page.locator("#training-box")).to_be_visible(timeout=60_000)
            expect(page.locator("#status")).to_have_text("scored", timeout=240_000)
            expect(page.locator("#training-text")).to_contain_text("trained in")
            expect(page.locator("#training-text")).to_contain_text("model sha256")
            page.locator("#training-box summary").click()
            expect(page.locator("#training-log")).to_contain_text("saved weights.npz")

            page.goto(f"{url}/?track=offline")
            row = page.locator("#leaderboard tr.entry").first
            expect(row.locator(".method")).to_have_text("behaviour cloning", timeout=10_000)
            expect(row.locator(".team")).to_have_text("offline-team")
            browser.close()
    finally:
        stop(worker)
