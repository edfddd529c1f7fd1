"""Watching episodes: the replay API's visibility rules and the replay pages in Chromium (the
slider and the play button move the vehicles drawn). Screenshots at desktop and phone width land
in ``ARENA_SCREENSHOTS`` when it is set."""

from __future__ import annotations

import json
import re
import shutil

import httpx
import pytest

from arena.suite import load_suite, public_suite_dir
from server.core.artifacts import artifact_store
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import ScenarioResult, Submission
from tests.server.api.test_browser import CHROMIUM
from tests.server.api.test_browser_pages import DESKTOP, PHONE, browser, offline_page, shoot
from tests.server.builders import bearer, make_team, seed_scored
from tests.server.live import api_server
from tests.server.service_stack import shared_dir
from tests.settings import env_only
from tests.sim.builders import recorded_episode

__all__ = ["browser"]  # the Chromium fixture, shared with the other page tests
ADMIN = "organiser-secret"
PUBLIC_SUITE = load_suite(public_suite_dir(env_only().suites))
PUBLIC_ID = "p000_left_turn_t_low"

# A live API process over a recorded episode (module fixture `served`).
pytestmark = pytest.mark.slow


def with_episode(db, store, submission_id: int, suite, record) -> None:
    """The submission's run evaluated the scenario of ``record`` from ``suite``."""
    key = f"records/{submission_id}/two_lanes.npz"
    store.put(key, record)
    with db.session() as session:
        run = session.get(Submission, submission_id).runs[-1]
        run.suite_dir = str(suite)
        session.add(
            ScenarioResult(
                run_id=run.id,
                scenario_id="two_lanes",
                family="cruise",
                status="done",
                reason="collision",
                record_key=key,
            )
        )


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    root = shared_dir("arena-replays-")
    settings = env_only(
        storage={"data_dir": root / "data"},
        suites={"hidden_suite_dir": root / "hidden"},
        service={"admin_token": ADMIN},
    )
    (root / "data").mkdir()
    upgrade_database(settings.storage.resolved_database_url)
    db = Database(settings.storage.resolved_database_url)
    suite, record = recorded_episode(root / "episode")
    store = artifact_store(settings.storage, db)
    team_id, token = make_team(db, "watchers")
    other_id, _ = make_team(db, "others")
    ids = {
        "validation": seed_scored(db, team_id, (1.0, 800.0, 0.1, 0.1), phase="validation"),
        "final": seed_scored(db, team_id, (1.0, 800.0, 0.1, 0.1), phase="final"),
        "other": seed_scored(db, other_id, (1.0, 800.0, 0.1, 0.1), phase="validation"),
    }
    for submission_id in ids.values():
        with_episode(db, store, submission_id, suite, record)
    db.dispose()
    log = tmp_path_factory.mktemp("replays") / "api.log"
    with api_server(settings, log) as (url, _):
        yield url, token, ids
    shutil.rmtree(root, ignore_errors=True)


@pytest.mark.slow
def test_team_watches_its_own_episodes_of_a_full_visibility_phase_only(served):
    url, token, ids = served
    api = f"{url}/api/v1"
    mine = f"{api}/submissions/{ids['validation']}/replays"
    own = httpx.get(f"{mine}/two_lanes", headers=bearer(token))
    assert own.status_code == 200
    data = own.json()
    assert data["scenario_id"] == "two_lanes" and data["frames"] == 60 and data["map"]["lanes"]
    assert [a["done_reason"] for a in data["agents"]] == ["collision", "max_episode_steps"]
    hidden = httpx.get(f"{api}/submissions/{ids['final']}/replays/two_lanes", headers=bearer(token))
    assert hidden.status_code == 403 and "organisers only" in hidden.json()["detail"]
    theirs = httpx.get(f"{api}/submissions/{ids['other']}/replays/two_lanes", headers=bearer(token))
    assert theirs.status_code == 404  # another team's submission does not exist for this one
    missing = httpx.get(f"{mine}/nope", headers=bearer(token))
    assert missing.status_code == 404 and "no recorded episode" in missing.json()["detail"]
    anonymous = httpx.get(f"{mine}/two_lanes")
    assert anonymous.status_code == 401
    bad = httpx.get(f"{mine}/..%2Fx", headers=bearer(token))
    assert bad.status_code in (404, 422)


def test_organisers_watch_every_episode_hidden_phases_included(served):
    url, token, ids = served
    path = f"{url}/api/v1/admin/submissions/{ids['final']}/replays/two_lanes"
    assert httpx.get(path, headers=bearer(ADMIN)).json()["frames"] == 60
    assert httpx.get(path, headers=bearer(token)).status_code == 401


@pytest.mark.slow
def test_anyone_watches_the_expert_drive_a_public_scenario(served):
    url, _, _ = served
    first = httpx.get(f"{url}/api/v1/scenarios/public/{PUBLIC_ID}/replay", timeout=120)
    assert first.status_code == 200
    data = first.json()
    assert data["scenario_id"] == PUBLIC_ID and data["map"]["junctions"]
    assert data["agents"][0]["done_reason"] == "reached_goal"
    again = httpx.get(f"{url}/api/v1/scenarios/public/{PUBLIC_ID}/replay", timeout=120)
    assert again.json() == data  # kept, not simulated again with other results
    # Encoded once and kept: the same bytes, an entity tag, and 304 for a client that has them.
    assert again.content == first.content and again.headers["etag"] == first.headers["etag"]
    assert "max-age" in again.headers["cache-control"]
    unchanged = httpx.get(
        f"{url}/api/v1/scenarios/public/{PUBLIC_ID}/replay",
        headers={"If-None-Match": first.headers["etag"]},
    )
    assert unchanged.status_code == 304 and unchanged.content == b""
    unknown = httpx.get(f"{url}/api/v1/scenarios/public/p999_nothing/replay")
    assert unknown.status_code == 404 and "no public scenario" in unknown.json()["detail"]


def apart_vertically(a: dict, b: dict) -> bool:
    return a["y1"] <= b["y0"] or b["y1"] <= a["y0"]


def drawn(page) -> dict[str, dict]:
    vehicles = page.evaluate("() => document.getElementById('replay').replay.drawn")
    return {v["id"]: v for v in vehicles}


@pytest.mark.browser
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian's chromium")
def test_submission_page_links_each_episode_and_the_slider_moves_the_vehicles(served, browser):
    from playwright.sync_api import expect

    url, token, ids = served
    for name, viewport in (("desktop", DESKTOP), ("phone", PHONE)):
        page = offline_page(browser, url, viewport)
        page.goto(f"{url}/submit")
        page.evaluate(f"sessionStorage.setItem('arena-token', {json.dumps(token)})")
        page.goto(f"{url}/submissions/{ids['validation']}")
        link = page.locator("#episodes a", has_text="cruise #1")
        expect(link).to_be_visible()
        shoot(page, f"submission-episodes-{name}")
        link.click()
        expect(page).to_have_url(f"{url}/submissions/{ids['validation']}/replays/two_lanes")
        expect(page.locator("#replay")).to_have_attribute("data-frame", "0")
        expect(page.locator(".replay-counter")).to_contain_text("step 1 / 60")
        start = drawn(page)
        # Side by side at the start: the labels of the two agents and their goals overlap
        # neither each other nor any vehicle.
        boxes = page.evaluate("document.getElementById('replay').replay.labels")
        cars = page.evaluate("document.getElementById('replay').replay.vehicleBoxes")
        assert len(boxes) == 4 and len(cars) == len(start)
        for i, a in enumerate(boxes):
            for b in [*boxes[i + 1 :], *cars]:
                assert a["x1"] <= b["x0"] or b["x1"] <= a["x0"] or apart_vertically(a, b), (a, b)
        canvas = page.locator("canvas.replay-view")
        before = canvas.screenshot()
        page.locator(".replay-scrub").fill("40")
        expect(page.locator(".replay-counter")).to_contain_text("step 41 / 60")
        later = drawn(page)
        # Agent_0 crashed at step 23: gone; Agent_1 and the traffic moved on.
        assert "Agent_0" not in later and "Agent_0" in start
        assert later["Agent_1"]["x"] > start["Agent_1"]["x"] + 30
        assert later["slow"]["x"] > start["slow"]["x"]
        assert canvas.screenshot() != before
        page.click(".replay-event")  # the collision marker jumps to it
        expect(page.locator(".replay-counter")).to_contain_text("step 23 / 60")
        assert page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
        shoot(page, f"replay-submission-{name}")
        page.goto(f"{url}/submissions/{ids['final']}/replays/two_lanes")
        expect(page.locator("#replay .error")).to_contain_text("organisers only")
        assert page.refused == []
        page.close()


@pytest.mark.browser
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian's chromium")
def test_public_scenario_replay_plays_from_the_scenarios_page(served, browser):
    from playwright.sync_api import expect

    url, _, _ = served
    for name, viewport in (("desktop", DESKTOP), ("phone", PHONE)):
        page = offline_page(browser, url, viewport)
        page.goto(f"{url}/")
        page.click("header a[href='/scenarios']")
        # Rows can be counted before the style sheet applies; widths are measured after it.
        page.wait_for_load_state("load")
        expect(page.locator("#scenarios tbody tr")).to_have_count(len(PUBLIC_SUITE.scenarios))
        assert page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
        shoot(page, f"scenarios-{name}")
        page.click(f"a[href='/scenarios/{PUBLIC_ID}/replay']")
        expect(page.locator("#replay")).to_have_attribute("data-frame", "0", timeout=60000)
        start = drawn(page)["Agent_0"]
        page.click(".replay-play")
        expect(page.locator("#replay")).not_to_have_attribute("data-frame", "0")
        # A frame past 20 (an attribute match: the page's CSP forbids evaluating strings).
        past_20 = re.compile(r"^(2[1-9]|[3-9][0-9]|[0-9]{3,})$")
        expect(page.locator("#replay")).to_have_attribute("data-frame", past_20)
        page.click(".replay-play")
        moved = drawn(page)["Agent_0"]
        assert (moved["x"], moved["y"]) != (start["x"], start["y"])
        # Clicking the end of the timeline jumps there.
        box = page.locator("canvas.replay-timeline").bounding_box()
        page.mouse.click(box["x"] + box["width"] - 2, box["y"] + box["height"] / 2)
        frames = page.evaluate("document.getElementById('replay').replay.data.frames")
        expect(page.locator("#replay")).to_have_attribute("data-frame", str(frames - 1))
        assert page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
        shoot(page, f"replay-public-{name}")
        assert page.refused == []
        page.close()
