"""Organiser actions that re-drive evaluations: re-queue, re-run, re-train, re-score, the
trained model for audit, service status."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import func, select

from arena.config import Settings
from evaluator.scoring import ProfileError, ScoringProfile, load_profile
from server.core.artifacts import ArtifactStore
from server.core.db import Database
from server.core.queue import BROKER_ERRORS, TaskQueue
from server.models import EvaluationRun, Submission, utcnow
from server.services import evaluation, scoring, training
from server.services.errors import Conflict, InvalidInput, NotFound
from server.services.evaluation import RunPlan, lock
from server.status import (
    ACTIVE_RUN,
    ACTIVE_TRAINING,
    SUBMISSION_MOVES,
    RunStatus,
    SubmissionStatus,
    advance,
)


def requeue(db: Database, settings: Settings, queue: TaskQueue, submission_id: int) -> str:
    """Send an unfinished submission's work again (after lost messages or a dead worker).
    Safe to repeat: tasks skip what is already done."""
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        validating = submission.status == SubmissionStatus.validating
    if validating:
        # A validation held by a live worker ignores the re-sent task (its lease fences it).
        queue.validate(submission_id)
        return "validation re-sent"
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        plan = None
        if submission.status == SubmissionStatus.received:
            submission.status = advance(
                submission.status, SubmissionStatus.queued, SUBMISSION_MOVES
            )
        # A training still held by a live worker ignores the re-sent task; a dead worker's is
        # handed out by the reaper once its lease expires.
        trainings = [job.id for job in submission.trainings if job.status in ACTIVE_TRAINING]
        training_id = None
        if submission.status == SubmissionStatus.queued:
            submission.queued_at = utcnow()
        elif trainings:
            training_id = trainings[-1]
        else:
            runs = [run for run in submission.runs if run.status in ACTIVE_RUN]
            if not runs:
                raise Conflict(
                    f"submission {submission_id} is {submission.status} with no evaluation in "
                    "progress; use rerun for a new attempt"
                )
            pending = evaluation.pending_episodes(runs[-1])
            runs[-1].lease_expires_at = evaluation.lease_until(settings)
            plan = RunPlan(run_id=runs[-1].id, episodes=pending, aggregate=not pending)
    if training_id is not None:
        queue.train(training_id)
        return "training re-sent"
    if plan is None:
        queue.evaluate(submission_id)
        return "evaluation queued"
    queue.send(plan)
    if plan.episodes:
        return f"{len(plan.episodes)} episode(s) re-sent"
    return "aggregation re-sent"


def rerun(db: Database, settings: Settings, queue: TaskQueue, submission_id: int) -> int:
    """A new simulation attempt; returns its attempt number."""
    with db.session() as session:
        plan = evaluation.rerun(session, settings, submission_id)
        attempt = session.get(EvaluationRun, plan.run_id).attempt
    queue.send(plan)
    return attempt


def retrain(db: Database, settings: Settings, queue: TaskQueue, submission_id: int) -> int:
    """A new training attempt of an offline submission, from scratch (then its evaluation);
    returns its attempt number."""
    with db.session() as session:
        job = training.retrain(session, settings, submission_id)
        training_id, attempt = job.id, job.attempt
    queue.train(training_id)
    return attempt


@dataclass(frozen=True)
class TrainedModel:
    """The stored trained output of a submission's latest successful training."""

    key: str
    sha256: str
    size: int  # [bytes]
    attempt: int

    @property
    def file_name(self) -> str:
        return f"model-{self.sha256[:12]}.tar.gz"


def trained_model(db: Database, submission_id: int) -> TrainedModel:
    with db.read_session() as session:
        submission = session.get(Submission, submission_id)
        if submission is None:
            raise NotFound(f"no submission {submission_id}")
        job = training.latest_trained(submission)
        if job is None or job.model_key is None:
            raise NotFound(f"submission {submission_id} has no trained output")
        return TrainedModel(job.model_key, job.model_sha256, job.model_size, job.attempt)


def scoring_profile(name: str) -> ScoringProfile:
    try:
        return load_profile(name)
    except ProfileError as exc:
        raise InvalidInput(str(exc)) from exc


def rescore_targets(db: Database, submission_id: int | None) -> list[int]:
    """Run ids to re-score: the given submission's scored runs, or every scored run."""
    with db.read_session() as session:
        query = select(EvaluationRun.id).where(EvaluationRun.status == RunStatus.scored)
        if submission_id is not None:
            query = query.where(EvaluationRun.submission_id == submission_id)
        return list(session.scalars(query.order_by(EvaluationRun.id)))


def rescore_run(
    db: Database, store: ArtifactStore, run_id: int, profile_name: str | None
) -> dict[str, float]:
    """Recompute a scored run from its stored records (no simulation)."""
    with db.session() as session:
        run = lock(session, EvaluationRun, run_id)
        if run.status != RunStatus.scored:
            raise Conflict(f"run {run_id} is {run.status}; only scored runs can be re-scored")
        profile = scoring_profile(profile_name or run.scoring_profile)
        summary = scoring.run_summary(run, profile, store)
        if summary.uncharged:
            raise Conflict(
                f"run {run_id}: the records of {', '.join(summary.uncharged)} cannot be scored"
            )
        run_score = scoring.run_score(summary)
        if run_score is None:
            raise Conflict(f"run {run_id} has no charged scenario to score")
        run.scoring_profile = profile.name
        run.scoring_version = str(profile.version)
        evaluation.write_score(session, run, run_score, profile.name, str(profile.version))
        return run_score.metrics


@dataclass(frozen=True)
class StuckRun:
    run_id: int
    submission_id: int
    worker: str
    lease_expires_at: datetime | None


@dataclass(frozen=True)
class ServiceStatus:
    queue_depth: int | None
    workers: list[str] | None
    submissions: dict[str, int]
    running_runs: int
    stuck_runs: list[StuckRun]


def service_status(db: Database, queue: TaskQueue) -> ServiceStatus:
    with db.read_session() as session:
        counts = dict(
            session.execute(
                select(Submission.status, func.count()).group_by(Submission.status)
            ).all()
        )
        active = list(
            session.scalars(select(EvaluationRun).where(EvaluationRun.status.in_(list(ACTIVE_RUN))))
        )
        moment = utcnow()
        stuck = [
            StuckRun(run.id, run.submission_id, run.worker, run.lease_expires_at)
            for run in active
            if run.lease_expires_at is not None and run.lease_expires_at < moment
        ]
        running = sum(run.status == RunStatus.running for run in active)
    try:
        depth = queue.depth()
        workers = queue.workers()
    except BROKER_ERRORS:  # reported as unreachable, not a crash
        depth = workers = None
    return ServiceStatus(
        queue_depth=depth,
        workers=workers,
        submissions={str(status): counts.get(status, 0) for status in SubmissionStatus},
        running_runs=running,
        stuck_runs=stuck,
    )
