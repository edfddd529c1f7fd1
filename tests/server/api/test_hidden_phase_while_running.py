"""A hidden phase shows nothing per episode until its run is over: no live failure reason (an
agent choosing how to fail had a covert channel of ~2.6 bits per episode), no per-episode
progress (each hidden episode's duration), no per-reason episode counts on the anonymous
/metrics, and no clock finer than ten minutes (issue 40: an agent sleeping an
observation-dependent time moved duration_s by 21.8 s). After scoring, the team sees what it
always did, with its duration and CPU coarse."""

from __future__ import annotations

from datetime import timedelta

import pytest

from server.models import Submission
from server.services import hidden_timing
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
    # Counted in quarters of the run; three episodes are too few for a quarter to span two, so
    # none shows until the run is over (a step would time one episode).
    assert live["progress"] == {"done": 0, "total": 4, "seeds": 1, "unit": "quarters"}
    assert live["duration_s"] is None and live["finished_at"] is None
    listed = client.get("/api/v1/submissions", headers=bearer(token)).json()
    assert listed[0]["progress"] == live["progress"]
    assert listed[0]["duration_s"] is None
    page = client.get(f"/api/v1/submissions/{sid}/download", headers=bearer(token))
    assert b"collision" not in page.content


def test_the_same_run_in_a_validation_phase_shows_everything_live(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="validation")
    evaluate_failing_everywhere(db, settings, sid, log="", episodes=2)
    live = detail(client, token, sid)
    assert live["progress"] == {"done": 2, "total": 3, "seeds": 1, "unit": "episodes"}
    assert live["duration_s"] is not None
    assert sum(n for family in live["failure_reasons"].values() for n in family.values()) == 2


def test_after_scoring_a_hidden_phase_shows_the_failure_counts(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="final")
    evaluate_failing_everywhere(db, settings, sid, log="")
    done = detail(client, token, sid)
    assert done["progress"] == {"done": 3, "total": 3, "seeds": 1, "unit": "episodes"}
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


def took(db, submission_id: int, seconds: float) -> None:
    """The submission ran for ``seconds`` (its start moved back, its end kept)."""
    with db.session() as session:
        submission = session.get(Submission, submission_id)
        submission.started_at = submission.finished_at - timedelta(seconds=seconds)


def test_a_hidden_runs_duration_does_not_carry_what_its_agent_saw(client, db, settings):
    """Two runs whose agents slept for different, observation-dependent times (21.8 s apart, as
    in issue 40) read the same: ten minutes, and no finish time to subtract from."""
    team, token = make_team(db, "alpha")
    shown = []
    for seconds in (95.0, 95.0 + 21.8):
        sid = queued_submission(db, team, phase="final")
        evaluate_failing_everywhere(db, settings, sid, log="")
        took(db, sid, seconds)
        view = detail(client, token, sid)
        assert view["status"] == "scored" and view["finished_at"] is None
        shown.append(view["duration_s"])
    assert shown == [600.0, 600.0]
    # The same in a validation phase: the exact figure, and its finish time.
    sid = queued_submission(db, team, phase="validation")
    evaluate_failing_everywhere(db, settings, sid, log="")
    took(db, sid, 95.0)
    view = detail(client, token, sid)
    assert view["duration_s"] == pytest.approx(95.0) and view["finished_at"] is not None


@pytest.mark.parametrize(
    ("done", "total", "quarters"),
    [
        (0, 3, 0),
        (2, 3, 0),  # too small: a quarter would be an episode
        (6, 7, 0),
        (1, 8, 0),
        (2, 8, 1),
        (3, 8, 1),
        (7, 8, 3),
        (31, 128, 0),
        (32, 128, 1),
        (127, 128, 3),
    ],
)
def test_progress_moves_in_quarters_whatever_the_suite_size(done, total, quarters) -> None:
    progress = hidden_timing.quarter_progress(done, total, seeds=1)
    assert (progress.done, progress.total, progress.unit) == (quarters, 4, "quarters")


def test_durations_and_cpu_round_up_to_whole_units() -> None:
    assert [hidden_timing.coarse_s(s) for s in (0.0, 1.0, 599.9, 600.0, 600.1)] == [
        600.0,
        600.0,
        600.0,
        600.0,
        1200.0,
    ]
    assert [hidden_timing.coarse_cpu_s(s) for s in (0.0, 0.4, 601.0)] == [0.0, 600.0, 1200.0]
