"""A run whose agent cannot start fails after its first scenarios with that one error, instead of
running (and listing) every scenario; an agent that started once runs them all."""

from __future__ import annotations

from server.models import EvaluationRun, Submission
from server.services import evaluation, scoring
from server.services.evaluation import ScenarioOutcomeIn
from server.status import RunStatus, SubmissionStatus
from tests.server.builders import make_team, queued_submission
from tests.server.test_evaluation_flow import claim, start

TORCH = (
    "Traceback (most recent call last):\n"
    '  File "policy.py", line 1, in <module>\n'
    "    import torch\n"
    "ModuleNotFoundError: No module named 'torch'\n"
)


def record(db, run_id, scenario_id, *, reason, steps, log=""):
    outcome = ScenarioOutcomeIn(
        scenario_id=scenario_id,
        status=scoring.FAILURE,
        reason=reason,
        log_tail=log,
        detail={
            "agents": [
                {
                    "id": "Agent_0",
                    "reached_goal": False,
                    "reason": reason,
                    "steps": steps,
                    "done_step": steps,
                }
            ]
        },
    )
    with db.session() as session:
        return evaluation.record_scenario(session, run_id, outcome)


def test_an_import_error_fails_the_run_after_two_scenarios(db, settings):
    team, _ = make_team(db, "alpha")
    submission_id = queued_submission(db, team)
    plan = start(db, settings, submission_id)
    assert len(plan.scenario_ids) == 3
    for sid in plan.scenario_ids[:2]:
        claim(db, settings, plan.run_id, sid)
        assert record(db, plan.run_id, sid, reason="agent_error", steps=0, log=TORCH) is False
    with db.session() as session:
        run = session.get(EvaluationRun, plan.run_id)
        submission = session.get(Submission, submission_id)
        assert run.status == RunStatus.failed
        assert submission.status == SubmissionStatus.failed
        assert submission.status_reason.startswith(
            "your agent could not start: ModuleNotFoundError: No module named 'torch'"
        )
        assert run.score is None  # never on the leaderboard
    # The third scenario's task finds the run over and does nothing.
    assert claim(db, settings, plan.run_id, plan.scenario_ids[2]) is None


def test_an_agent_that_drove_once_runs_every_scenario(db, settings):
    team, _ = make_team(db, "beta")
    submission_id = queued_submission(db, team)
    plan = start(db, settings, submission_id)
    first, *rest = plan.scenario_ids
    claim(db, settings, plan.run_id, first)
    record(db, plan.run_id, first, reason="collision", steps=0)  # it started: a driving failure
    for sid in rest:
        claim(db, settings, plan.run_id, sid)
        last = record(db, plan.run_id, sid, reason="agent_error", steps=0, log=TORCH)
    assert last is True  # every scenario finished: the run goes on to be aggregated
    with db.session() as session:
        assert evaluation.finish_run(session, plan.run_id) == RunStatus.scored
