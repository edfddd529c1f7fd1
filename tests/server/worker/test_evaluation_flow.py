"""The run life cycle in the database, as the Celery tasks drive it: fan-out, idempotent results,
aggregation, leases and the reaper, cancel, re-run and re-score."""

from __future__ import annotations

from datetime import timedelta

import pytest
from sqlalchemy import func, select, update

from arena.outcome import AgentOutcome, ScenarioStatus
from evaluator.runner import ScenarioOutcome
from server.core.artifacts import DatabaseStore
from server.core.queue import RunPlan, TaskQueue
from server.models import EvaluationRun, ScenarioResult, Submission, utcnow
from server.services import admin, evaluation
from server.services.errors import Conflict
from server.status import RunStatus, SubmissionStatus
from tests.server.builders import agent, claim_episode, make_team, queued_submission, scenario_ids


def start(db, settings, submission_id):
    with db.session() as session:
        return evaluation.start_evaluation(session, settings, submission_id)


def claim(db, settings, run_id, scenario_id, worker="w1"):
    with db.session() as session:
        return evaluation.claim_scenario(
            session, settings.service, settings.sandbox, run_id, scenario_id, worker
        )


def job_of(db, run_id, scenario_id) -> tuple[evaluation.ScenarioJob, str]:
    """The current claim on a scenario and its holder (as the worker holding it knows them)."""
    with db.session() as session:
        row = session.scalar(
            select(ScenarioResult).where(
                ScenarioResult.run_id == run_id, ScenarioResult.scenario_id == scenario_id
            )
        )
    job = evaluation.ScenarioJob(
        run_id=run_id,
        submission_id=0,
        scenario_id=scenario_id,
        scenario_dir="",
        upload_key="",
        claim_number=row.claim_number if row else 0,
    )
    return job, row.worker if row else ""


def finish(
    db,
    run_id,
    scenario_id,
    *,
    success=True,
    status=ScenarioStatus.done,
    record_key=None,
    claim=None,
):
    """Report a result as the worker holding the scenario does (or as ``claim`` = (job, worker))."""
    job, worker = claim or job_of(db, run_id, scenario_id)
    charged = status == ScenarioStatus.done
    outcome = ScenarioOutcome(
        scenario_id=scenario_id,
        status=status,
        steps=0,
        agents=(AgentOutcome(**agent(success)),) if charged else (),
        record_path=None,
        error=None if charged else "SUMO crashed",
    )
    with db.session() as session:
        return evaluation.record_scenario(
            session, job, worker, outcome, "agent output", record_key=record_key
        )


def aggregate(db, run_id):
    with db.session() as session:
        return evaluation.finish_run(session, DatabaseStore(db), run_id)


def status_of(db, submission_id):
    with db.session() as session:
        return session.get(Submission, submission_id).status


def expire_lease(db, run_id, scenario_id=None):
    """Let the run's lease lapse, and the claim's of ``scenario_id`` (all claims when None)."""
    past = utcnow() - timedelta(seconds=1)
    with db.session() as session:
        session.execute(
            update(EvaluationRun).where(EvaluationRun.id == run_id).values(lease_expires_at=past)
        )
        claims = update(ScenarioResult).where(ScenarioResult.run_id == run_id)
        if scenario_id is not None:
            claims = claims.where(ScenarioResult.scenario_id == scenario_id)
        session.execute(claims.values(lease_expires_at=past))


@pytest.fixture
def submission_id(db):
    team, _ = make_team(db, "alpha")
    return queued_submission(db, team)


def test_fan_out_results_and_aggregation(db, settings, submission_id):
    plan = start(db, settings, submission_id)
    assert len(scenario_ids(plan)) == 3 and not plan.aggregate
    assert start(db, settings, submission_id) is None  # a redelivered evaluate task
    assert status_of(db, submission_id) == SubmissionStatus.running
    ids = scenario_ids(plan)
    for sid in ids:
        assert claim(db, settings, plan.run_id, sid) is not None
    assert finish(db, plan.run_id, ids[0]) is False
    assert finish(db, plan.run_id, ids[1], success=False) is False
    assert finish(db, plan.run_id, ids[1]) is False  # duplicate delivery: ignored
    assert finish(db, plan.run_id, ids[2]) is True  # the last one: send the aggregation
    assert finish(db, plan.run_id, ids[2]) is False
    with db.session() as session:
        rows = session.scalar(select(func.count()).where(ScenarioResult.run_id == plan.run_id))
        assert rows == 3
    assert aggregate(db, plan.run_id) == RunStatus.scored
    assert aggregate(db, plan.run_id) is None  # a redelivered aggregation
    assert status_of(db, submission_id) == SubmissionStatus.scored
    with db.session() as session:
        score = session.get(EvaluationRun, plan.run_id).score
        assert score.completion == pytest.approx(1 / 3)
        assert score.time == pytest.approx((100 + 800 + 100) / 3)
        assert score.families["merge"]["scenarios"] == 1


def test_a_claim_is_exclusive_while_the_lease_lives(db, settings, submission_id):
    plan = start(db, settings, submission_id)
    sid = scenario_ids(plan)[0]
    assert claim(db, settings, plan.run_id, sid, "w1") is not None
    assert claim(db, settings, plan.run_id, sid, "w2") is None
    expire_lease(db, plan.run_id, sid)
    # The first worker stopped renewing the lease: another may take the scenario over.
    assert claim(db, settings, plan.run_id, sid, "w2") is not None
    assert finish(db, plan.run_id, sid) is False
    assert claim(db, settings, plan.run_id, sid, "w3") is None  # finished: nothing to do


def test_reaper_resends_stale_claims_and_lost_messages(db, settings, submission_id):
    plan = start(db, settings, submission_id)
    first, *rest = scenario_ids(plan)
    w1 = claim(db, settings, plan.run_id, first, "w1")
    with db.session() as session:
        assert (
            evaluation.reap(session, settings.service, queue_empty=True).plans == ()
        )  # lease valid
    # w1 died: its claim's lease lapses while the rest of the run's stays fresh (other workers
    # renew theirs). The claim alone is released and re-sent at once, even with a busy queue.
    expire_lease(db, plan.run_id, first)
    with db.session() as session:
        reaped = evaluation.reap(session, settings.service, queue_empty=False)
    assert [scenario_ids(p) for p in reaped.plans] == [(first,)]
    retaken = claim(db, settings, plan.run_id, first, "w2")
    assert retaken is not None and retaken.claim_number == 2  # the task gives up after too many
    assert claim(db, settings, plan.run_id, first, "w3") is None  # w2 holds it now
    # w1's episode was still running after all: its heartbeat learns it lost the claim, and its
    # result is fenced off.
    with db.session() as session:
        assert not evaluation.heartbeat(session, settings.service, w1, "w1")
        assert evaluation.heartbeat(session, settings.service, retaken, "w2")
    assert finish(db, plan.run_id, first, success=False, claim=(w1, "w1")) is False
    with db.session() as session:  # w2's lease is fresh: not re-sent again
        assert evaluation.reap(session, settings.service, queue_empty=True).plans == ()
    finish(db, plan.run_id, first, claim=(retaken, "w2"))
    with db.session() as session:
        row = session.scalar(select(ScenarioResult).where(ScenarioResult.scenario_id == first))
        assert (row.status, row.reason, row.worker) == ("done", "reached_goal", "")
    expire_lease(db, plan.run_id)
    with db.session() as session:
        # Never claimed, queue busy: the tasks may still be waiting their turn.
        assert evaluation.reap(session, settings.service, queue_empty=False).plans == ()
    with db.session() as session:
        reaped = evaluation.reap(session, settings.service, queue_empty=True)
    assert [scenario_ids(p) for p in reaped.plans] == [tuple(rest)]


def test_reaper_resends_a_submission_whose_first_task_was_lost(db, settings, submission_id):
    with db.session() as session:
        session.execute(update(Submission).values(queued_at=utcnow() - timedelta(hours=1)))
    with db.session() as session:
        assert evaluation.reap(session, settings.service, queue_empty=False).submission_ids == ()
    with db.session() as session:
        assert evaluation.reap(session, settings.service, queue_empty=True).submission_ids == (
            submission_id,
        )


def test_cancel_stops_a_running_evaluation(db, settings, submission_id):
    from server.services import submissions

    plan = start(db, settings, submission_id)
    job = claim(db, settings, plan.run_id, scenario_ids(plan)[0])
    submissions.cancel(db, TaskQueue(settings), submission_id)
    assert status_of(db, submission_id) == SubmissionStatus.cancelled
    with db.session() as session:
        assert not evaluation.heartbeat(session, settings.service, job, "w1")
        # A cancelled run shows no scenario as running.
        running = select(func.count()).where(ScenarioResult.status == "running")
        assert session.scalar(running) == 0
    assert finish(db, plan.run_id, scenario_ids(plan)[0], claim=(job, "w1")) is False
    assert claim(db, settings, plan.run_id, scenario_ids(plan)[1]) is None
    with pytest.raises(Conflict):
        submissions.cancel(db, TaskQueue(settings), submission_id)


def test_simulator_errors_only_fail_the_run(db, settings, submission_id):
    plan = start(db, settings, submission_id)
    for sid in scenario_ids(plan):
        claim(db, settings, plan.run_id, sid)
        finish(db, plan.run_id, sid, status=ScenarioStatus.simulator_error)
    assert aggregate(db, plan.run_id) == RunStatus.failed
    assert status_of(db, submission_id) == SubmissionStatus.failed


def test_a_score_covers_the_whole_suite_or_waits_for_an_organiser(db, settings, submission_id):
    plan = start(db, settings, submission_id)
    first, *rest = scenario_ids(plan)
    claim(db, settings, plan.run_id, first)
    finish(db, plan.run_id, first, status=ScenarioStatus.simulator_error)
    for sid in rest:
        claim(db, settings, plan.run_id, sid)
        finish(db, plan.run_id, sid)
    assert aggregate(db, plan.run_id) == RunStatus.failed
    with db.session() as session:
        run = session.get(EvaluationRun, plan.run_id)
        assert run.score is None
        assert "1 scenario(s) failed on our side" in run.error
        assert run.submission.failed_on_our_side  # not charged to the team's quota


def run_everything(db, settings, plan, success=True):
    for sid in scenario_ids(plan):
        claim(db, settings, plan.run_id, sid)
        finish(db, plan.run_id, sid, success=success)
    return aggregate(db, plan.run_id)


def test_rerun_is_a_new_attempt_and_the_old_score_stands_meanwhile(db, settings, submission_id):
    queue = TaskQueue(settings)
    first = start(db, settings, submission_id)
    run_everything(db, settings, first, success=False)
    assert admin.rerun(db, settings, queue, submission_id) == 2
    with pytest.raises(Conflict):
        admin.rerun(db, settings, queue, submission_id)  # one attempt at a time
    assert status_of(db, submission_id) == SubmissionStatus.scored
    with db.session() as session:
        second = session.scalar(select(EvaluationRun).where(EvaluationRun.attempt == 2))
        plan = RunPlan(run_id=second.id, episodes=evaluation.pending_episodes(second))
    run_everything(db, settings, plan, success=True)
    with db.session() as session:
        from server.services import submissions

        view = submissions.detail(session, session.get(Submission, submission_id))
    assert view.attempt == 2 and view.metrics.completion == 0.0


def test_rest_shows_the_latest_attempt_beside_the_score_that_stands(db, settings, submission_id):
    """A re-run that failed on our side left REST saying only ``scored`` (attempt 1): the
    team could not tell its re-run had run, nor that its failure was not theirs."""
    from server.services import submissions

    def view():
        with db.session() as session:
            return submissions.detail(session, session.get(Submission, submission_id))

    queue = TaskQueue(settings)
    run_everything(db, settings, start(db, settings, submission_id))
    assert view().latest_attempt.model_dump() == {"attempt": 1, "status": "scored", "error": ""}
    admin.rerun(db, settings, queue, submission_id)
    shown = view()
    assert (shown.status, shown.attempt) == (SubmissionStatus.scored, 1)
    assert (shown.latest_attempt.attempt, shown.latest_attempt.status) == (2, RunStatus.queued)
    with db.session() as session:
        second = session.scalar(select(EvaluationRun).where(EvaluationRun.attempt == 2))
        plan = RunPlan(run_id=second.id, episodes=evaluation.pending_episodes(second))
    for sid in scenario_ids(plan):
        claim(db, settings, plan.run_id, sid)
        finish(db, plan.run_id, sid, status=ScenarioStatus.simulator_error)
    aggregate(db, plan.run_id)
    shown = view()
    assert (shown.status, shown.attempt) == (SubmissionStatus.scored, 1)  # its score stands
    latest = shown.latest_attempt
    assert (latest.attempt, latest.status) == (2, RunStatus.failed)
    assert "failed on our side (not the submission's fault)" in latest.error


def test_rescore_recomputes_from_stored_results(db, settings, submission_id):
    plan = start(db, settings, submission_id)
    run_everything(db, settings, plan)
    targets = admin.rescore_targets(db, settings, submission_id=submission_id)
    assert [(t.run_id, t.submission_id, t.phase) for t in targets] == [
        (plan.run_id, submission_id, "final")
    ]
    profile, metrics = admin.rescore_run(db, settings.evaluation, DatabaseStore(db), plan.run_id)
    assert profile == "driving-smarts-2022"
    assert metrics["completion"] == 0.0 and metrics["time"] == 100.0
    with db.session() as session:
        assert session.get(EvaluationRun, plan.run_id).score.profile == "driving-smarts-2022"


def test_an_unreadable_record_fails_the_run_instead_of_wedging_it(
    db, settings, submission_id, tmp_path
):
    plan = start(db, settings, submission_id)
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"not an npz")
    DatabaseStore(db).put("runs/broken.npz", broken)
    for sid in scenario_ids(plan):
        claim(db, settings, plan.run_id, sid)
        finish(db, plan.run_id, sid, record_key="runs/broken.npz")
    assert aggregate(db, plan.run_id) == RunStatus.failed
    assert status_of(db, submission_id) == SubmissionStatus.failed
    with db.session() as session:
        assert "failed on our side" in session.get(EvaluationRun, plan.run_id).error


def test_each_episode_of_a_reactive_scenario_is_a_claim_of_its_own(db, settings, submission_id):
    """With 2 episodes per reactive scenario the run fans out 2 per scenario, each claimed and
    recorded on its own; the score is the mean over episodes and carries its interval."""
    from arena.episodes import Episode
    from server.services import phases
    from server.services.errors import NotFound

    phases.set_phase(db, settings, "final", phases.PhaseChanges(episodes_per_scenario=2))
    plan = start(db, settings, submission_id)
    ids = sorted({e.scenario_id for e in plan.episodes})
    assert sorted(plan.episodes) == [Episode(sid, k) for sid in ids for k in (0, 1)]
    with db.session() as session, pytest.raises(NotFound, match="no episode 2"):
        evaluation.claim_scenario(
            session, settings.service, settings.sandbox, plan.run_id, ids[0], "w1", 2
        )
    last = []
    for episode in plan.episodes:
        with db.session() as session:
            job = claim_episode(session, settings, plan, episode)
        assert job.key == episode
        # The first scenario fails in its second episode only.
        success = episode != Episode(ids[0], 1)
        outcome = ScenarioOutcome(
            scenario_id=episode.scenario_id,
            status=ScenarioStatus.done,
            steps=0,
            agents=(AgentOutcome(**agent(success)),),
            record_path=None,
            episode=episode.index,
        )
        with db.session() as session:
            last.append(evaluation.record_scenario(session, job, "w1", outcome, ""))
    assert last == [False] * 5 + [True]
    assert aggregate(db, plan.run_id) == RunStatus.scored
    with db.session() as session:
        run = session.get(EvaluationRun, plan.run_id)
        assert (run.episode_count, run.episodes_per_scenario) == (6, 2)
        assert run.score.completion == pytest.approx(0.5 / 3)
        assert run.score.completion_low <= run.score.completion <= run.score.completion_high
        assert run.score.completion_high > run.score.completion_low
