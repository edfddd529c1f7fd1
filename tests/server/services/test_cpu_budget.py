"""The evaluation's CPU budget in the service, as the worker's tasks drive it: a run whose agent
passed its budget fails, charged to the team, and its remaining episodes are not run; under the
budget it is scored; a phase's limits win over the settings' and each run records its own."""

from __future__ import annotations

import pytest
from sqlalchemy import select

from server.core.artifacts import DatabaseStore
from server.models import EvaluationRun, Submission
from server.services import evaluation, phases
from server.services.errors import InvalidInput
from tests.server.builders import bearer, make_team, queued_submission, report_episode
from tests.settings import with_fields

# The suite fixture has three scenarios, one episode each.
TINY = phases.PhaseChanges(step_cpu_s=0.1, episode_cpu_s=0.5, evaluation_cpu_s=1.0)


def run_episodes(db, settings, submission_id, cpu_s: float, only: int | None = None) -> list[bool]:
    """Every episode (or the first ``only``: the run stays under way) claimed and reported done
    as a worker does, its agent having used ``cpu_s`` of CPU; per episode, whether it could be
    claimed (False: not run)."""
    with db.session() as session:
        plan = evaluation.start_evaluation(session, settings, submission_id)
    claimed, last = [], False
    for episode in plan.episodes[:only]:
        reported = report_episode(db, settings, plan, episode, reached_goal=True, agent_cpu_s=cpu_s)
        claimed.append(reported is not None)
        last = last or bool(reported)
    if last:  # the aggregation task
        with db.session() as session:
            evaluation.finish_run(session, DatabaseStore(db), plan.run_id)
    return claimed


def test_a_run_past_its_budget_fails_charged_to_the_team(client, db, settings):
    phases.set_phase(db, settings, "final", TINY)
    team, token = make_team(db, "a")
    sid = queued_submission(db, team)

    # 0.6 s per episode: the second passes the 1 s budget, the third is never run.
    assert run_episodes(db, settings, sid, cpu_s=0.6) == [True, True, False]

    with db.read_session() as session:
        submission = session.get(Submission, sid)
        run = session.scalar(select(EvaluationRun))
        assert (submission.status, run.status) == ("failed", "failed")
        assert not submission.failed_on_our_side  # the team's: it counts towards the quota
        reason = submission.status_reason
    # A hidden phase: rounded up to 10 minutes, and not where it stopped (issue 40).
    assert "used 600.0 s of CPU, over" in reason and "episode(s)" not in reason
    assert "budget of 1 s" in reason and "remaining episodes were not run" in reason
    assert "act() cheaper" in reason
    detail = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()
    assert detail["status_reason"] == reason
    # The team's view of a hidden phase: rounded up to 10 minutes (hidden_timing.coarse_cpu_s).
    assert detail["agent_cpu"] == {
        "used_s": 600.0,
        "budget_s": 1.0,
        "evaluations": 1,
        "most_used_s": 600.0,
    }
    with db.read_session() as session:
        run_id = session.scalar(select(EvaluationRun.id))
        assert evaluation.agent_cpu_used(session, run_id) == pytest.approx(1.2)  # organisers


def test_a_run_under_its_budget_is_scored(client, db, settings):
    phases.set_phase(db, settings, "final", TINY)
    team, token = make_team(db, "a")
    sid = queued_submission(db, team)

    assert run_episodes(db, settings, sid, cpu_s=0.3) == [True, True, True]

    detail = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()
    assert detail["status"] == "scored"
    # The team's view of a hidden phase: rounded up to 10 minutes (hidden_timing.coarse_cpu_s).
    assert detail["agent_cpu"] == {
        "used_s": 600.0,
        "budget_s": 1.0,
        "evaluations": 1,
        "most_used_s": 600.0,
    }
    with db.read_session() as session:
        run_id = session.scalar(select(EvaluationRun.id))
        assert evaluation.agent_cpu_used(session, run_id) == pytest.approx(0.9)  # organisers
    limits = detail["phase_window"]["cpu_limits"]
    assert limits == {"step_s": 0.1, "episode_s": 0.5, "evaluation_s": 1.0}


def test_the_phase_override_wins_over_the_setting(client, db, settings):
    settings = with_fields(settings, sandbox={"evaluation_cpu_s": 1000.0})
    team, token = make_team(db, "a")

    # Without an override the setting applies: 3 x 0.6 s is well under 1000 s.
    first = queued_submission(db, team)
    assert run_episodes(db, settings, first, cpu_s=0.6) == [True, True, True]

    phases.set_phase(db, settings, "final", TINY)
    second = queued_submission(db, team)
    with db.session() as session:
        plan = evaluation.start_evaluation(session, settings, second)
        job = evaluation.claim_scenario(
            session,
            settings.service,
            settings.sandbox,
            plan.run_id,
            plan.episodes[0].scenario_id,
            "w1",
        )
        run = session.get(EvaluationRun, plan.run_id)
        # The run records the limits it is evaluated under; the worker's job carries them.
        assert (run.step_cpu_s, run.episode_cpu_s, run.evaluation_cpu_s) == (0.1, 0.5, 1.0)
        assert (job.limits.step_s, job.limits.episode_s, job.limits.evaluation_s) == (
            0.1,
            0.5,
            1.0,
        )
    with db.read_session() as session:
        assert session.get(Submission, first).status == "scored"
        assert session.scalar(
            select(EvaluationRun.evaluation_cpu_s).where(EvaluationRun.submission_id == first)
        ) == pytest.approx(1000.0)

    # The phase window every team reads shows the phase's limits.
    window = client.get("/api/v1/team", headers=bearer(token)).json()["allowances"]
    final = next(a["phase"] for a in window if a["phase"]["name"] == "final")
    assert final["cpu_limits"]["evaluation_s"] == 1.0

    # Cleared, the settings' apply again.
    phase = phases.set_phase(db, settings, "final", phases.PhaseChanges(default_cpu_limits=True))
    assert phases.cpu_limits(phase, settings.sandbox) == settings.sandbox.cpu_limits


def test_the_phase_refuses_limits_that_do_not_grow(db, settings):
    with pytest.raises(InvalidInput, match="more than 0"):
        phases.set_phase(db, settings, "final", phases.PhaseChanges(evaluation_cpu_s=0))
    with pytest.raises(InvalidInput, match="must grow"):
        phases.set_phase(db, settings, "final", phases.PhaseChanges(evaluation_cpu_s=10.0))


@pytest.mark.parametrize(("phase", "shown"), [("validation", True), ("final", False)])
def test_a_hidden_phase_shows_the_cpu_only_once_the_run_is_over(client, db, settings, phase, shown):
    """Read after each episode, the CPU an agent used would carry what it saw of a hidden
    scenario: in a hidden phase it is shown once the run is over, like failure reasons."""
    team, token = make_team(db, "a")
    sid = queued_submission(db, team, phase=phase)
    run_episodes(db, settings, sid, cpu_s=0.25, only=1)
    detail = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()
    assert detail["status"] == "running"
    if shown:
        assert detail["agent_cpu"] == {
            "used_s": 0.25,
            "budget_s": settings.sandbox.evaluation_cpu_s,
            "evaluations": 1,
            "most_used_s": 0.25,
        }
    else:
        assert detail["agent_cpu"] is None
