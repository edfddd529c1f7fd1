"""Server-rendered pages, /healthz, /metrics, /scenarios/public and the admin HTTP routes."""

from __future__ import annotations

import pytest

from server.services import evaluation
from tests.server.builders import bearer, make_team, queued_submission, scenario_ids, seed_scored
from tests.server.conftest import ADMIN_TOKEN
from tests.settings import with_fields

FAMILIES = {
    "cruise": {"completion": 0.0, "time": 300.0, "humanness": 0.1, "rules": 0.0, "scenarios": 2},
    "merge": {"completion": 1.0, "time": 800.0, "humanness": 0.3, "rules": 0.1, "scenarios": 1},
}


def test_leaderboard_page_lists_entries_with_families_and_chart(client, db):
    team, _ = make_team(db, "alpha")
    seed_scored(db, team, (0.3333, 466.7, 0.17, 0.03), method_name="my planner", families=FAMILIES)
    html = client.get("/").text
    assert "my planner" in html and "alpha" in html
    assert "0.3333" in html
    # The per-family breakdown and its SVG bar chart: one bar per family, merge full width.
    assert html.count('class="bar"') == 2
    assert 'width="220.0"' in html
    assert "No scored submission" in client.get("/?track=offline").text


def test_submit_and_submission_pages_render(client):
    submit = client.get("/submit").text
    for field in ('id="token"', 'id="track"', 'id="method_name"', 'id="description"', 'id="file"'):
        assert field in submit
    assert "Arena.submissionPage(7" in client.get("/submissions/7").text
    assert client.get("/static/app.js").status_code == 200


def test_healthz_and_metrics(client, db, settings):
    assert client.get("/api/v1/healthz").json() == {
        "status": "ok",
        "database": True,
        "broker": True,
    }
    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    with db.session() as session:
        plan = evaluation.start_evaluation(session, settings, sid)
    with db.session() as session:
        evaluation.claim_scenario(
            session, settings.service, settings.sandbox, plan.run_id, scenario_ids(plan)[0], "w"
        )
    text = client.get("/api/v1/metrics", headers=bearer(settings.service.admin_token)).text
    assert "arena_queue_depth" in text
    assert "arena_running_evaluations 1.0" in text
    assert 'arena_submissions{status="running"} 1.0' in text
    assert 'arena_episodes{reason="",status="running"} 1.0' in text


def test_public_scenarios_list(client, suite_dir):
    scenarios = client.get("/api/v1/scenarios/public").json()
    assert sorted(s["family"] for s in scenarios) == ["cruise", "cruise", "merge"]


def test_admin_routes_need_the_admin_token(client, db):
    team, token = make_team(db, "alpha")
    sid = seed_scored(db, team, (0.5, 400.0, 0.1, 0.0))
    path = f"/api/v1/admin/submissions/{sid}/disqualify"
    assert client.post(path, json={"reason": "x"}).status_code == 401
    assert client.post(path, json={"reason": "x"}, headers=bearer(token)).status_code == 401
    response = client.post(path, json={"reason": "x"}, headers=bearer(ADMIN_TOKEN))
    assert response.status_code == 200 and response.json()["status"] == "disqualified"
    # Illegal moves are refused, not applied.
    again = client.post(path, json={"reason": "x"}, headers=bearer(ADMIN_TOKEN))
    assert again.status_code == 409
    listing = client.get("/api/v1/admin/submissions", headers=bearer(ADMIN_TOKEN)).json()
    assert [item["id"] for item in listing] == [sid]


@pytest.mark.slow
def test_healthz_degrades_and_uploads_still_land_when_the_broker_is_down(settings, db, tmp_path):
    from fastapi.testclient import TestClient

    from server.app import create_app
    from tests.server.builders import pack_example
    from tests.server.live import free_port

    down = with_fields(settings, storage={"broker_url": f"redis://127.0.0.1:{free_port()}/0"})
    _, token = make_team(db, "alpha")
    with TestClient(create_app(down)) as client:
        response = client.get("/api/v1/healthz")
        assert response.status_code == 503
        assert response.json() == {"status": "degraded", "database": True, "broker": False}
        # The upload is stored, validating; the workers' reaper sends its validation once the
        # broker is back.
        zip_path = pack_example("random", tmp_path)
        created = client.post(
            "/api/v1/submissions",
            headers=bearer(token),
            data={"method_name": "random"},
            files={"file": ("a.zip", zip_path.read_bytes(), "application/zip")},
        )
        assert created.status_code == 202 and created.json()["status"] == "validating"
