"""A hidden phase shows nothing per episode until its run is over: no live failure reason (an
agent choosing how to fail had a covert channel of ~2.6 bits per episode), no per-episode
progress (each hidden episode's duration), no per-reason episode counts on the anonymous
/metrics. After scoring, the team sees what it always did."""

from __future__ import annotations

from tests.server.builders import (
    bearer,
    evaluate_failing_everywhere,
    make_team,
    queued_submission,
)

# The suite of the fixtures: cruise x2, merge x1 (three episodes).


def detail(client, token, submission_id) -> dict:
    return client.get(f"/api/v1/submissions/{submission_id}", headers=bearer(token)).json()


def test_a_hidden_run_under_way_shows_no_failure_reason_and_coarse_progress(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="final")
    evaluate_failing_everywhere(db, settings, sid, log="", episodes=2)
    live = detail(client, token, sid)
    assert live["status"] == "running"
    assert live["failure_reasons"] == {}
    # Counted in quarters of the run, rounded down: 2 of 3 episodes reads as 1 of 3 (half of
    # the run); the next change comes only when the run is over.
    assert live["progress"] == {"done": 1, "total": 3, "seeds": 1}
    listed = client.get("/api/v1/submissions", headers=bearer(token)).json()
    assert listed[0]["progress"] == {"done": 1, "total": 3, "seeds": 1}
    page = client.get(f"/api/v1/submissions/{sid}/download", headers=bearer(token))
    assert b"collision" not in page.content


def test_the_same_run_in_a_validation_phase_shows_everything_live(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="validation")
    evaluate_failing_everywhere(db, settings, sid, log="", episodes=2)
    live = detail(client, token, sid)
    assert live["progress"] == {"done": 2, "total": 3, "seeds": 1}
    assert sum(n for family in live["failure_reasons"].values() for n in family.values()) == 2


def test_after_scoring_a_hidden_phase_shows_the_failure_counts(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="final")
    evaluate_failing_everywhere(db, settings, sid, log="")
    done = detail(client, token, sid)
    assert done["progress"] == {"done": 3, "total": 3, "seeds": 1}
    assert done["failure_reasons"] == {"cruise": {"collision": 2}, "merge": {"collision": 1}}


def test_metrics_show_episode_outcomes_only_to_the_organisers(client, db, settings):
    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="final")
    evaluate_failing_everywhere(db, settings, sid, log="", episodes=1)
    anonymous = client.get("/api/v1/metrics").text
    assert "arena_queue_depth" in anonymous and "arena_submissions" in anonymous
    assert "arena_episodes" not in anonymous and "collision" not in anonymous
    organisers = client.get("/api/v1/metrics", headers=bearer(settings.service.admin_token)).text
    assert 'arena_episodes{reason="collision",status="done"} 1.0' in organisers
