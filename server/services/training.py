"""Training jobs of offline (Track 2) submissions, as database transitions (a job kind of the
engine: claimed, leased, fenced and reaped by :mod:`server.jobs.leases`).

An offline submission goes ``queued -> training -> running``: :func:`start_training` makes its
first seed set, one job per seed of its phase (:mod:`server.services.seed_sets`); a worker claims
each (:func:`claim_training`), renews the lease with the progress the
team sees (:func:`heartbeat`) and records the end (:func:`record_trained`, which creates the
evaluation run of the trained output, or :func:`record_failed`). A worker that dies stops
renewing its lease and :func:`reap` hands the job to another, which trains again from scratch.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from arena.config import ServiceSettings, Settings
from arena.neutralise.storable import storable_text
from server.core.queue import RunPlan
from server.jobs import leases
from server.jobs.leases import lease_until
from server.models import Submission, TrainingJob
from server.models import utcnow as now
from server.services import phases, seed_sets
from server.services.errors import Conflict
from server.services.evaluation import (
    cannot_start,
    create_run,
    end_submission,
    lock,
    stop_seed_set,
)
from server.status import (
    ACTIVE_RUN,
    ACTIVE_TRAINING,
    SUBMISSION_MOVES,
    TRAINING_MOVES,
    SubmissionStatus,
    TrainingStatus,
    advance,
)
from server.tracks import Track

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainingClaim:
    """What a worker needs to train one submission."""

    training_id: int
    submission_id: int
    upload_key: str  # the submission's zip in the artifact store
    claim_number: int  # 1 for the first claim; more after workers died holding it
    seed: int = 0  # ARENA_TRAIN_SEED

    def __str__(self) -> str:
        return f"{self.training_id} (claim {self.claim_number})"


def _latest(session: Session, submission_id: int, column) -> int:
    query = select(func.max(column)).where(TrainingJob.submission_id == submission_id)
    return session.scalar(query) or 0


def _job(
    service: ServiceSettings,
    submission_id: int,
    *,
    attempt: int,
    seed_set: int,
    seed: int,
    seeds: int,
) -> TrainingJob:
    return TrainingJob(
        submission_id=submission_id,
        attempt=attempt,
        seed_set=seed_set,
        seed=seed,
        seeds=seeds,
        status=TrainingStatus.queued,
        claim_number=0,
        elapsed_s=0.0,
        log_tail="",
        failure="",
        error="",
        model_sha256="",
        model_size=0,
        lease_expires_at=lease_until(service),
    )


def _new_set(
    session: Session, service: ServiceSettings, submission: Submission
) -> list[TrainingJob]:
    """A new seed set: one queued job per seed of the submission's phase."""
    seeds = phases.get_phase(session, submission.phase).training_seeds
    attempt = _latest(session, submission.id, TrainingJob.attempt)
    seed_set = 1 + _latest(session, submission.id, TrainingJob.seed_set)
    jobs = [
        _job(
            service,
            submission.id,
            attempt=attempt + 1 + seed,
            seed_set=seed_set,
            seed=seed,
            seeds=seeds,
        )
        for seed in range(seeds)
    ]
    session.add_all(jobs)
    session.flush()
    return jobs


def replace_lost_seeds(
    session: Session, service: ServiceSettings, submission: Submission
) -> list[TrainingJob]:
    """A new job, in the same set, for each seed of the latest set lost on our side while the
    submission went on (:func:`server.services.seed_sets.lost_seeds`): that seed trains again
    from scratch, the others keep what they did."""
    attempt = _latest(session, submission.id, TrainingJob.attempt)
    jobs = [
        _job(
            service,
            submission.id,
            attempt=attempt + 1 + number,
            seed_set=lost.seed_set,
            seed=lost.seed,
            seeds=lost.seeds,
        )
        for number, lost in enumerate(seed_sets.lost_seeds(submission))
    ]
    session.add_all(jobs)
    session.flush()
    if jobs:
        submission.status_reason = ""  # it said the seed waits for an organiser
    return jobs


def ended(session: Session, training_id: int) -> bool:
    """Whether the job is over (trained, failed or cancelled): nothing will resume it."""
    job = session.get(TrainingJob, training_id)
    return job is None or job.status not in ACTIVE_TRAINING


def start_training(
    session: Session, service: ServiceSettings, submission_id: int
) -> tuple[int, ...]:
    """The training jobs (one per seed) of a queued offline submission; none for a freestyle
    one or one no longer queued (a duplicate delivery)."""
    submission = lock(session, Submission, submission_id)
    if submission.track != Track.offline or submission.status != SubmissionStatus.queued:
        return ()
    submission.status = advance(submission.status, SubmissionStatus.training, SUBMISSION_MOVES)
    submission.started_at = now()
    return tuple(job.id for job in _new_set(session, service, submission))


def retrain(session: Session, service: ServiceSettings, submission_id: int) -> list[TrainingJob]:
    """A new training attempt, from scratch, of a scored or failed offline submission: a new
    seed set, every seed trained again; its score stands until the new set is scored."""
    submission = lock(session, Submission, submission_id)
    if submission.track != Track.offline:
        raise Conflict(f"submission {submission_id} is {submission.track}: it has no training")
    if submission.status not in (SubmissionStatus.scored, SubmissionStatus.failed):
        raise Conflict(
            f"submission {submission_id} is {submission.status}: only scored or failed "
            "submissions can be retrained"
        )
    busy = [j for j in submission.trainings if j.status in ACTIVE_TRAINING]
    if busy or any(run.status in ACTIVE_RUN for run in submission.runs):
        raise Conflict(f"submission {submission_id} already has a training or evaluation running")
    return _new_set(session, service, submission)


def latest_trained(submission: Submission) -> TrainingJob | None:
    trained = [job for job in submission.trainings if job.status == TrainingStatus.trained]
    return trained[-1] if trained else None


def shown_training(submission: Submission) -> TrainingJob | None:
    """The job whose progress is shown, of the latest seed set: a failed seed (why the
    submission failed), else the first still under way, else the last."""
    jobs = seed_sets.latest_set(submission)
    failed = [job for job in jobs if job.status == TrainingStatus.failed]
    active = [job for job in jobs if job.status in ACTIVE_TRAINING]
    if failed or active:
        return (failed or active)[0]
    return jobs[-1] if jobs else None


def claim_training(
    session: Session, service: ServiceSettings, training_id: int, worker: str
) -> TrainingClaim | None:
    """Mark a job as trained by ``worker``; None if it is over or held by a live lease."""
    job = lock(session, TrainingJob, training_id)
    if job.status not in ACTIVE_TRAINING:
        return None
    claim_number = leases.claim(job, worker, service)
    if claim_number is None:
        return None
    if job.status == TrainingStatus.queued:
        job.status = advance(job.status, TrainingStatus.training, TRAINING_MOVES)
        job.started_at = now()
    return TrainingClaim(
        training_id=job.id,
        submission_id=job.submission_id,
        upload_key=job.submission.upload_key,
        claim_number=claim_number,
        seed=job.seed,
    )


def _fence(claim: TrainingClaim, worker: str) -> tuple:
    return leases.fence(
        TrainingJob, worker, claim.claim_number, TrainingJob.id == claim.training_id
    )


def heartbeat(
    session: Session,
    service: ServiceSettings,
    claim: TrainingClaim,
    worker: str,
    elapsed_s: float | None = None,
    log_tail: str | None = None,
) -> bool:
    """Extend the lease and show the progress (when there is some yet); False when the claim is
    no longer ``worker``'s (cancelled, or handed to another worker): the training must stop."""
    progress = (
        {}
        if elapsed_s is None
        else {"elapsed_s": elapsed_s, "log_tail": storable_text(log_tail or "")}
    )
    return leases.renew(session, service, TrainingJob, _fence(claim, worker), **progress)


def release(session: Session, claim: TrainingClaim, worker: str) -> bool:
    """Hand the job back (its worker is stopping, or retries later): any worker may claim it."""
    return leases.release(session, TrainingJob, _fence(claim, worker))


def _finish(session: Session, claim: TrainingClaim, worker: str) -> TrainingJob | None:
    job = lock(session, TrainingJob, claim.training_id)
    if not leases.owned(job, worker, claim.claim_number):
        return None
    leases.drop(job)
    job.finished_at = now()
    return job


def record_trained(
    session: Session,
    settings: Settings,
    claim: TrainingClaim,
    worker: str,
    *,
    elapsed_s: float,
    log_tail: str,
    model_key: str,
    model_sha256: str,
    model_size: int,
) -> RunPlan | None:
    """Store the trained output and start its evaluation; returns the run's scenario tasks, or
    None if the claim was superseded or the submission was cancelled meanwhile."""
    job = _finish(session, claim, worker)
    if job is None:
        return None
    job.status = advance(job.status, TrainingStatus.trained, TRAINING_MOVES)
    job.elapsed_s, job.log_tail = elapsed_s, storable_text(log_tail)
    job.model_key, job.model_sha256, job.model_size = model_key, model_sha256, model_size
    submission = lock(session, Submission, claim.submission_id)
    if submission.status == SubmissionStatus.training:
        submission.status = advance(submission.status, SubmissionStatus.running, SUBMISSION_MOVES)
    elif submission.status not in (
        SubmissionStatus.running,  # another seed trained first
        SubmissionStatus.scored,
        SubmissionStatus.failed,
    ):  # cancelled or disqualified
        return None
    try:
        return create_run(session, settings, submission, training=job)
    except phases.PhaseMisconfigured as exc:
        if submission.status == SubmissionStatus.running:
            cannot_start(submission, exc.message)
        return None


def record_failed(
    session: Session,
    claim: TrainingClaim,
    worker: str,
    *,
    failure: str,
    error: str,
    elapsed_s: float = 0.0,
    log_tail: str = "",
    ours: bool = False,
) -> bool:
    """A training that ended without a model: the named ``failure`` (the team's, charged) or,
    with ``ours``, a failure on our side (not charged). The team's failure fails the submission:
    its seed set can no longer be scored, so the other seeds stop. Ours, on one seed of several,
    fails that seed alone: the others go on and it waits for an organiser's requeue
    (:func:`replace_lost_seeds`). False if the claim was superseded."""
    job = _finish(session, claim, worker)
    if job is None:
        return False
    job.status = advance(job.status, TrainingStatus.failed, TRAINING_MOVES)
    error = storable_text(error)  # the training's own words, from its log
    job.failure, job.error = failure, error
    job.elapsed_s, job.log_tail = elapsed_s, storable_text(log_tail)
    submission = lock(session, Submission, claim.submission_id)
    going = submission.status in (SubmissionStatus.training, SubmissionStatus.running)
    if ours and seed_sets.several(job):
        log.error(
            "submission %d: seed %d (training %d) failed on our side (%s): waiting for "
            "arena admin submissions requeue %d",
            submission.id,
            job.seed,
            job.id,
            failure,
            submission.id,
        )
        if going:
            submission.status_reason = seed_sets.seed_lost(job, "training", failure, "trains again")
        return True
    if going:
        reason = (
            seed_sets.reason(job, f"{failure}: {error}")
            if ours
            else seed_sets.training_failed(job, failure, error)
        )
        end_submission(submission, reason, ours=ours)
    stop_seed_set(session, submission)
    return True


def reap(session: Session, service: ServiceSettings, *, queue_empty: bool) -> tuple[int, ...]:
    """Jobs to send again: those whose worker stopped renewing the lease (released at once),
    and, when the queue is empty, those whose task was lost before any worker held them."""
    waiting = leases.unheld(TrainingJob).where(TrainingJob.status.in_(list(ACTIVE_TRAINING)))
    stale, lost = leases.reap(
        session, service, leases.expired(TrainingJob), waiting if queue_empty else None
    )
    return tuple(job.id for job in stale + lost)
