"""The life of an evaluation run, as database transitions. Celery tasks, the reaper and the admin
CLI call these; each takes the row lock first and returns early when the work is already done, so
any of them can run twice (a redelivered task, a re-queue) without double-counting anything.

Callers send the tasks these functions ask for only after the function's transaction committed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import timedelta
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from sqlalchemy import delete, func, select, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session

from arena.config import Settings
from evaluator import failures
from evaluator.scoring import load_profile
from server.models import EvaluationRun, LeaderboardGeneration, ScenarioResult, Score, Submission
from server.models import utcnow as now
from server.services import scoring
from server.services.errors import Conflict, NotFound
from server.services.suites import evaluation_suite_dir, load_suite
from server.status import (
    ACTIVE_RUN,
    RUN_MOVES,
    SUBMISSION_MOVES,
    RunStatus,
    SubmissionStatus,
    advance,
)


@dataclass(frozen=True)
class RunPlan:
    """Scenario tasks to send for a run (and whether its aggregation is due)."""

    run_id: int
    scenario_ids: tuple[str, ...] = ()
    aggregate: bool = False


@dataclass(frozen=True)
class ScenarioJob:
    """What a worker needs to run one scenario of a run."""

    run_id: int
    submission_id: int
    scenario_id: str
    scenario_dir: str
    storage_dir: str
    attempt: int  # 1 for the first claim; more after workers died holding it


@dataclass(frozen=True)
class ScenarioOutcomeIn:
    """A finished scenario, as the worker reports it."""

    scenario_id: str
    status: str  # one of scoring.FINISHED
    reason: str = ""
    steps: int = 0
    record_path: str | None = None
    log_tail: str = ""
    detail: dict[str, Any] = field(default_factory=dict)


def lock(session: Session, model, row_id: int):
    row = session.scalar(select(model).where(model.id == row_id).with_for_update())
    if row is None:
        raise NotFound(f"no {model.__tablename__[:-1].replace('_', ' ')} {row_id}")
    return row


def bump_leaderboard(session: Session) -> None:
    updated = session.execute(
        update(LeaderboardGeneration)
        .where(LeaderboardGeneration.id == 1)
        .values(value=LeaderboardGeneration.value + 1)
    )
    if updated.rowcount == 0:
        session.add(LeaderboardGeneration(id=1, value=1))


def lease_until(settings: Settings):
    return now() + timedelta(seconds=settings.lease_seconds)


def create_run(session: Session, settings: Settings, submission: Submission) -> RunPlan:
    """A new attempt on the evaluation suite; every scenario of it still to run."""
    suite = load_suite(evaluation_suite_dir(settings))
    profile = load_profile(settings.scoring_profile)
    attempt = 1 + (
        session.scalar(
            select(func.max(EvaluationRun.attempt)).where(
                EvaluationRun.submission_id == submission.id
            )
        )
        or 0
    )
    run = EvaluationRun(
        submission_id=submission.id,
        attempt=attempt,
        status=RunStatus.queued,
        suite_dir=str(suite.root),
        manifest_sha256=suite.manifest_sha256,
        scenario_count=len(suite.manifest.scenarios),
        scoring_profile=profile.name,
        scoring_version=str(profile.version),
        lease_expires_at=lease_until(settings),
    )
    session.add(run)
    session.flush()
    ids = tuple(entry.id for entry in suite.manifest.scenarios)
    return RunPlan(run_id=run.id, scenario_ids=ids, aggregate=not ids)


def start_evaluation(session: Session, settings: Settings, submission_id: int) -> RunPlan | None:
    """First attempt of a queued submission; None if it is no longer queued (done already,
    cancelled, or a duplicate delivery of the same task)."""
    submission = lock(session, Submission, submission_id)
    if submission.status != SubmissionStatus.queued:
        return None
    submission.status = advance(submission.status, SubmissionStatus.running, SUBMISSION_MOVES)
    submission.started_at = now()
    return create_run(session, settings, submission)


def rerun(session: Session, settings: Settings, submission_id: int) -> RunPlan:
    """A new simulation attempt of a scored or failed submission; its current score stands
    until the new attempt is scored."""
    submission = lock(session, Submission, submission_id)
    if submission.status not in (SubmissionStatus.scored, SubmissionStatus.failed):
        raise Conflict(
            f"submission {submission_id} is {submission.status}: only scored or failed "
            "submissions can be re-run"
        )
    if any(run.status in ACTIVE_RUN for run in submission.runs):
        raise Conflict(f"submission {submission_id} already has an evaluation in progress")
    return create_run(session, settings, submission)


def claim_scenario(
    session: Session, settings: Settings, run_id: int, scenario_id: str, worker: str
) -> ScenarioJob | None:
    """Mark a scenario as being run by ``worker``; None if the run is over or the scenario is
    finished or held by a worker whose lease is still valid."""
    run = lock(session, EvaluationRun, run_id)
    if run.status not in ACTIVE_RUN:
        return None
    existing = session.scalar(
        select(ScenarioResult).where(
            ScenarioResult.run_id == run_id, ScenarioResult.scenario_id == scenario_id
        )
    )
    if existing is not None and existing.status != scoring.RUNNING:
        return None
    lease_valid = run.lease_expires_at is not None and run.lease_expires_at > now()
    if existing is not None and existing.worker and lease_valid:
        return None
    suite = load_suite(Path(run.suite_dir))
    family = suite.family_of().get(scenario_id)
    if family is None:
        raise NotFound(f"scenario {scenario_id} is not in the suite of run {run_id}")
    if existing is None:
        existing = ScenarioResult(
            run_id=run_id,
            scenario_id=scenario_id,
            family=family,
            status=scoring.RUNNING,
            worker=worker,
            attempts=0,
        )
        session.add(existing)
    existing.worker = worker
    existing.attempts += 1
    if run.status == RunStatus.queued:
        run.status = advance(run.status, RunStatus.running, RUN_MOVES)
        run.started_at = now()
    run.worker = worker
    run.lease_expires_at = lease_until(settings)
    return ScenarioJob(
        run_id=run_id,
        submission_id=run.submission_id,
        scenario_id=scenario_id,
        scenario_dir=str(suite.scenario_dir(scenario_id)),
        storage_dir=run.submission.storage_dir,
        attempt=existing.attempts,
    )


def heartbeat(session: Session, settings: Settings, run_id: int, worker: str) -> bool:
    """Extend the run's lease; False when the run is no longer active (cancelled: stop)."""
    renewed = session.execute(
        update(EvaluationRun)
        .where(EvaluationRun.id == run_id, EvaluationRun.status.in_(list(ACTIVE_RUN)))
        .values(lease_expires_at=lease_until(settings), worker=worker)
    )
    return renewed.rowcount == 1


def record_scenario(session: Session, run_id: int, outcome: ScenarioOutcomeIn) -> bool:
    """Store a finished scenario. Returns True exactly once per run: when this call finished its
    last scenario (the caller then sends the aggregation)."""
    run = lock(session, EvaluationRun, run_id)
    if run.status not in ACTIVE_RUN:
        return False
    values = {
        "status": outcome.status,
        "reason": outcome.reason,
        "steps": outcome.steps,
        "record_path": outcome.record_path,
        "log_tail": outcome.log_tail,
        "detail": outcome.detail,
    }
    family = load_suite(Path(run.suite_dir)).family_of()
    _insert_if_absent(session, run_id, outcome.scenario_id, family[outcome.scenario_id])
    finished = session.execute(
        update(ScenarioResult)
        .where(
            ScenarioResult.run_id == run_id,
            ScenarioResult.scenario_id == outcome.scenario_id,
            ScenarioResult.status == scoring.RUNNING,
        )
        .values(**values)
    )
    if finished.rowcount == 0:
        return False  # a duplicate delivery: the first one already recorded this scenario
    if _give_up_if_agent_cannot_start(session, run):
        return False
    return finished_count(session, run_id) == run.scenario_count


def _give_up_if_agent_cannot_start(session: Session, run: EvaluationRun) -> bool:
    """Fail the run when its first finished scenarios all show the agent failing before its first
    step (import or init error, init timeout): one error for the team instead of one per scenario.
    The run's other scenario tasks find it inactive and do nothing."""
    results = session.scalars(
        select(ScenarioResult)
        .where(
            ScenarioResult.run_id == run.id,
            ScenarioResult.status.in_(list(scoring.FINISHED)),
        )
        .order_by(ScenarioResult.id)
    ).all()
    if len(results) < failures.FAIL_FAST_AFTER or len(results) >= run.scenario_count:
        return False
    agents = [[SimpleNamespace(**a) for a in r.detail.get("agents", [])] for r in results]
    if not all(
        r.status == scoring.FAILURE and failures.never_started(a)
        for r, a in zip(results, agents, strict=True)
    ):
        return False
    error = failures.startup_error(results[0].log_tail).splitlines()
    run.error = (
        f"your agent could not start: {error[-1] if error else results[0].reason} "
        f"(the same in the first {len(results)} scenarios; the others were not run)"
    )
    run.status = advance(run.status, RunStatus.failed, RUN_MOVES)
    run.finished_at = now()
    submission = lock(session, Submission, run.submission_id)
    if submission.status == SubmissionStatus.running:
        submission.status = advance(submission.status, SubmissionStatus.failed, SUBMISSION_MOVES)
        submission.status_reason = run.error
        submission.finished_at = now()
    return True


def _insert_if_absent(session: Session, run_id: int, scenario_id: str, family: str) -> None:
    dialect = session.get_bind().dialect.name
    insert = postgresql.insert if dialect == "postgresql" else sqlite.insert
    session.execute(
        insert(ScenarioResult)
        .values(
            run_id=run_id,
            scenario_id=scenario_id,
            family=family,
            status=scoring.RUNNING,
            detail={},
            worker="",
            attempts=1,
            created_at=now(),
        )
        .on_conflict_do_nothing(index_elements=["run_id", "scenario_id"])
    )


def finished_count(session: Session, run_id: int) -> int:
    return session.scalar(
        select(func.count())
        .select_from(ScenarioResult)
        .where(
            ScenarioResult.run_id == run_id,
            ScenarioResult.status.in_(list(scoring.FINISHED)),
        )
    )


def finish_run(session: Session, run_id: int) -> RunStatus | None:
    """Score a run whose scenarios are all finished; None if it was finished already."""
    run = lock(session, EvaluationRun, run_id)
    if run.status not in ACTIVE_RUN:
        return None
    if finished_count(session, run_id) < run.scenario_count:
        raise Conflict(f"run {run_id} still has scenarios to run")
    submission = lock(session, Submission, run.submission_id)
    results = list(run.results)
    run_score = None
    if any(result.status == scoring.INFRASTRUCTURE_ERROR for result in results):
        run.error = "the evaluation infrastructure failed on some scenarios; re-run it"
    else:
        try:
            run_score = scoring.score_results(results, load_profile(run.scoring_profile))
        except scoring.UnscorableRecord as exc:
            run.error = exc.message
        else:
            if run_score is None:
                run.error = "no scenario could be simulated (simulator errors only)"
    run.finished_at = now()
    if run_score is None:
        run.status = advance(run.status, RunStatus.failed, RUN_MOVES)
        if submission.status == SubmissionStatus.running:
            submission.status = advance(
                submission.status, SubmissionStatus.failed, SUBMISSION_MOVES
            )
            submission.status_reason = run.error
            submission.finished_at = now()
        return run.status
    write_score(session, run, run_score, run.scoring_profile, run.scoring_version)
    run.status = advance(run.status, RunStatus.scored, RUN_MOVES)
    if submission.status in (SubmissionStatus.running, SubmissionStatus.failed):
        submission.status = advance(submission.status, SubmissionStatus.scored, SUBMISSION_MOVES)
        submission.status_reason = ""
        submission.finished_at = now()
    return run.status


def write_score(
    session: Session, run: EvaluationRun, run_score: scoring.RunScore, profile: str, version: str
) -> None:
    session.execute(delete(Score).where(Score.run_id == run.id))
    session.add(
        Score(
            run_id=run.id,
            profile=profile,
            profile_version=version,
            families=run_score.families,
            **run_score.metrics,
        )
    )
    bump_leaderboard(session)


def pending_scenarios(run: EvaluationRun) -> tuple[str, ...]:
    """Scenario ids of the run's suite that have no finished result yet, in manifest order."""
    done = {result.scenario_id for result in run.results if result.status in scoring.FINISHED}
    suite = load_suite(Path(run.suite_dir))
    return tuple(entry.id for entry in suite.manifest.scenarios if entry.id not in done)


def cancel_run(session: Session, run: EvaluationRun) -> tuple[str, ...]:
    """Cancel an active run; returns the ids of its scenarios that have not finished."""
    run.status = advance(run.status, RunStatus.cancelled, RUN_MOVES)
    run.finished_at = now()
    return pending_scenarios(run)


@dataclass(frozen=True)
class Reaped:
    """Work the reaper found lost: scenario tasks and aggregations to send again, and queued
    submissions whose first task never started."""

    plans: tuple[RunPlan, ...] = ()
    submission_ids: tuple[int, ...] = ()


def reap(session: Session, settings: Settings, *, queue_empty: bool) -> Reaped:
    """Find evaluations whose lease expired and renew it for the work this returns.

    A scenario claimed by a worker that stopped renewing the lease is re-sent at once. Work never
    claimed at all is re-sent only when the queue is empty: until then it may just be waiting its
    turn (and a lost message is found as soon as the queue drains, e.g. after a broker restart
    without persistence).
    """
    moment = now()
    plans = []
    expired = session.scalars(
        select(EvaluationRun)
        .where(
            EvaluationRun.status.in_(list(ACTIVE_RUN)),
            EvaluationRun.lease_expires_at < moment,
        )
        .with_for_update()
    )
    for run in expired:
        stale_claims = [result for result in run.results if result.status == scoring.RUNNING]
        if not (stale_claims or queue_empty):
            continue
        # Release the claims of the worker that went silent, so the re-sent tasks can take them.
        for claim in stale_claims:
            claim.worker = ""
        pending = pending_scenarios(run)
        run.lease_expires_at = lease_until(settings)
        plans.append(RunPlan(run_id=run.id, scenario_ids=pending, aggregate=not pending))
    submission_ids: list[int] = []
    if queue_empty:
        waiting = session.scalars(
            select(Submission)
            .where(
                Submission.status == SubmissionStatus.queued,
                Submission.queued_at < moment - timedelta(seconds=settings.lease_seconds),
            )
            .with_for_update()
        )
        for submission in waiting:
            submission.queued_at = moment
            submission_ids.append(submission.id)
    return Reaped(plans=tuple(plans), submission_ids=tuple(submission_ids))
