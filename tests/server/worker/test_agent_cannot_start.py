"""A run whose agent cannot start fails after its first scenarios with that one error, instead of
running (and listing) every scenario; an agent that started once runs them all."""

from __future__ import annotations

from arena.outcome import AgentOutcome, ScenarioStatus
from evaluator.runner import ScenarioOutcome
from server.core.artifacts import DatabaseStore
from server.models import EvaluationRun, Submission
from server.services import evaluation, submissions
from server.status import RunStatus, SubmissionStatus
from tests.server.builders import make_team, queued_submission, scenario_ids
from tests.server.worker.test_evaluation_flow import claim, start

TORCH = (
    "Traceback (most recent call last):\n"
    '  File "policy.py", line 1, in <module>\n'
    "    import torch\n"
    "ModuleNotFoundError: No module named 'torch'\n"
)


def record(db, job, *, reason, steps, log="", observed=True):
    outcome = ScenarioOutcome(
        observed=observed,
        scenario_id=job.scenario_id,
        status=ScenarioStatus.done,
        steps=steps,
        agents=(
            AgentOutcome(
                id="Agent_0", reached_goal=False, reason=reason, steps=steps, done_step=steps
            ),
        ),
        record_path=None,
    )
    with db.session() as session:
        return evaluation.record_scenario(session, job, "w1", outcome, log)


def test_an_import_error_fails_the_run_after_two_scenarios(db, settings):
    team, _ = make_team(db, "alpha")
    submission_id = queued_submission(db, team, phase="validation")
    plan = start(db, settings, submission_id)
    assert len(scenario_ids(plan)) == 3
    for sid in scenario_ids(plan)[:2]:
        job = claim(db, settings, plan.run_id, sid)
        assert record(db, job, reason="agent_error", steps=0, log=TORCH) is False
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
    assert claim(db, settings, plan.run_id, scenario_ids(plan)[2]) is None


def test_in_a_hidden_phase_the_startup_error_keeps_the_agents_words_out(db, settings):
    team, _ = make_team(db, "gamma")
    submission_id = queued_submission(db, team)  # final: a hidden phase
    plan = start(db, settings, submission_id)
    for sid in scenario_ids(plan)[:2]:
        job = claim(db, settings, plan.run_id, sid)
        record(db, job, reason="agent_error", steps=0, log=TORCH)
    with db.session() as session:
        reason = session.get(Submission, submission_id).status_reason
    assert reason.startswith("your agent could not start: agent_error")
    assert "torch" not in reason and "validation phase" in reason


def test_an_agent_that_drove_once_runs_every_scenario(db, settings):
    team, _ = make_team(db, "beta")
    submission_id = queued_submission(db, team)
    plan = start(db, settings, submission_id)
    first, *rest = scenario_ids(plan)
    job = claim(db, settings, plan.run_id, first)
    record(db, job, reason="collision", steps=0)  # it started: a driving failure
    for sid in rest:
        job = claim(db, settings, plan.run_id, sid)
        last = record(db, job, reason="agent_error", steps=0, log=TORCH)
    assert last is True  # every scenario finished: the run goes on to be aggregated
    with db.session() as session:
        assert evaluation.finish_run(session, DatabaseStore(db), plan.run_id) == RunStatus.scored


def failed_fast(db, settings, name: str, *, observed: bool) -> tuple[int, int]:
    team, _ = make_team(db, name)
    submission_id = queued_submission(db, team)  # final: a hidden phase
    plan = start(db, settings, submission_id)
    for sid in scenario_ids(plan)[:2]:
        job = claim(db, settings, plan.run_id, sid)
        record(db, job, reason="agent_error", steps=0, log=TORCH, observed=observed)
    return team, submission_id


def test_an_agent_that_could_not_be_loaded_gives_the_quota_back(db, settings):
    """As docs/submissions.md says: nothing of a scenario reached it, so nothing is charged."""
    team, submission_id = failed_fast(db, settings, "delta", observed=False)
    with db.session() as session:
        submission = session.get(Submission, submission_id)
        assert submission.status == SubmissionStatus.failed and submission.never_started
        assert "does not count against your daily quota" in submission.status_reason
        used = submissions.quota_used(
            session, team, "final", submission.track, submission.created_at
        )
    assert used == 0


def test_an_agent_that_failed_at_its_first_observation_is_charged(db, settings):
    """It saw a hidden scenario: a free run would carry what it saw to its team for nothing
    (issue 40: an agent sleeping an observation-dependent time, then raising)."""
    team, submission_id = failed_fast(db, settings, "epsilon", observed=True)
    with db.session() as session:
        submission = session.get(Submission, submission_id)
        assert submission.status == SubmissionStatus.failed and not submission.never_started
        assert "counts against your daily quota" in submission.status_reason
        used = submissions.quota_used(
            session, team, "final", submission.track, submission.created_at
        )
    assert used == 1
