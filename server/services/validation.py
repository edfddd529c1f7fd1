"""Validating an upload, as database transitions: the API reserves the quota slot and stores the
zip (:func:`reserve`, :func:`stored`); a worker claims the validation job (:func:`claim`, leased
like every job of the engine, :mod:`server.services.leases`), validates the zip in the sandbox and
records the verdict through the fence (:func:`record_valid`, which queues the submission, or
:func:`record_rejected`, which gives its quota try back).

A team has at most one upload ``validating`` (a unique partial index, migration 0010), so parallel
uploads cannot cost more intakes than one at a time, and none beyond the quota.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from arena.config import ServiceSettings
from server.core.db import Database
from server.models import Submission, Team, UploadValidation, utcnow
from server.services import leases
from server.services.errors import Conflict
from server.services.evaluation import lock
from server.status import SUBMISSION_MOVES, SubmissionStatus, advance
from server.tracks import Track

BUSY = (
    "an upload of your team is still being validated{which}: wait until it is queued or "
    "rejected, then upload again"
)


@dataclass(frozen=True)
class ValidationClaim:
    """What a worker needs to validate one upload."""

    submission_id: int
    upload_key: str
    needs_training: bool  # an offline (Track 2) submission: train.py is required
    claim_number: int  # the fence token


def check_not_busy(session: Session, team_id: int) -> None:
    """Refuse early (before the body is read) when the team's slot is taken."""
    busy = session.scalar(
        select(Submission.id).where(
            Submission.team_id == team_id, Submission.status == SubmissionStatus.validating
        )
    )
    if busy is not None:
        raise Conflict(BUSY.format(which=f" (submission {busy})"))


def reserve(
    db: Database, service: ServiceSettings, team_id: int, fields: dict, check_quota: Callable
) -> tuple[int, str]:
    """The new submission's id and upload key, ``validating``: the team's one validation slot
    and one try of its quota, taken in one transaction (``check_quota(session)`` raises when
    none is left)."""
    try:
        with db.session() as session:
            lock(session, Team, team_id)  # serialises one team's uploads (quota)
            check_not_busy(session, team_id)
            check_quota(session)
            submission = Submission(
                team_id=team_id,
                upload_key=f"submissions/{uuid.uuid4().hex}/upload.zip",
                file_sha256="",
                file_size=0,
                status=SubmissionStatus.validating,
                **fields,
            )
            session.add(submission)
            session.flush()
            # Leased from the start: the reaper re-sends it only if no worker took it in time.
            session.add(
                UploadValidation(
                    submission_id=submission.id,
                    worker="",
                    claims=0,
                    lease_expires_at=leases.lease_until(service),
                )
            )
            return submission.id, submission.upload_key
    except IntegrityError as exc:  # the partial unique index: another upload won the race
        raise Conflict(BUSY.format(which="")) from exc


def give_back(db: Database, submission_id: int) -> None:
    """The upload never passed its cheap checks: the reservation leaves no trace."""
    with db.session() as session:
        submission = session.get(Submission, submission_id)
        if submission is None or submission.status != SubmissionStatus.validating:
            return
        job = session.scalar(
            select(UploadValidation).where(UploadValidation.submission_id == submission_id)
        )
        if job is not None:
            session.delete(job)
            session.flush()
        session.delete(submission)


def stored(db: Database, submission_id: int, sha256: str, size: int) -> None:
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        submission.file_sha256, submission.file_size = sha256, size


def _job(session: Session, submission_id: int) -> UploadValidation | None:
    return session.scalar(
        select(UploadValidation)
        .where(UploadValidation.submission_id == submission_id)
        .with_for_update()
    )


def claim(
    session: Session, service: ServiceSettings, submission_id: int, worker: str
) -> ValidationClaim | None:
    """Take the validation for ``worker``; None when it is over or held by a live lease."""
    submission = lock(session, Submission, submission_id)
    job = _job(session, submission_id)
    if job is None or submission.status != SubmissionStatus.validating or leases.held(job):
        return None
    job.claims += 1
    job.started_at = job.started_at or utcnow()
    leases.take(job, worker, service)
    return ValidationClaim(
        submission_id=submission_id,
        upload_key=submission.upload_key,
        needs_training=submission.track == Track.offline,
        claim_number=job.claims,
    )


def _fence(claim: ValidationClaim, worker: str) -> tuple:
    return (
        UploadValidation.submission_id == claim.submission_id,
        UploadValidation.finished_at.is_(None),
        UploadValidation.worker == worker,
        UploadValidation.claims == claim.claim_number,
    )


def renew(session: Session, service: ServiceSettings, claim: ValidationClaim, worker: str) -> bool:
    return leases.renew(session, service, UploadValidation, _fence(claim, worker))


def release(session: Session, claim: ValidationClaim, worker: str) -> bool:
    return leases.release(session, UploadValidation, _fence(claim, worker))


def _finish(session: Session, claim: ValidationClaim, worker: str) -> Submission | None:
    """The submission, when the claim is still ``worker``'s and it is still validating."""
    submission = lock(session, Submission, claim.submission_id)
    job = _job(session, claim.submission_id)
    if job is None or (job.worker, job.claims) != (worker, claim.claim_number):
        return None  # a duplicate delivery, or a superseded claim: the verdict is not ours
    leases.drop(job)
    job.finished_at = utcnow()
    return submission if submission.status == SubmissionStatus.validating else None


def record_valid(
    session: Session,
    claim: ValidationClaim,
    worker: str,
    *,
    deps_key: str | None,
    explanation: str | None,
) -> bool:
    """Queue the validated submission; False when the verdict is not to be written."""
    submission = _finish(session, claim, worker)
    if submission is None:
        return False
    submission.status = advance(submission.status, SubmissionStatus.queued, SUBMISSION_MOVES)
    submission.queued_at = utcnow()
    submission.deps_key = deps_key
    if not submission.description.strip():
        submission.description = (explanation or "").strip()
    return True


def record_rejected(
    session: Session, claim: ValidationClaim, worker: str, reason: str, *, ours: bool
) -> bool:
    """``rejected`` (the zip broke a rule: ``reason`` names it; the quota try is given back)
    or, with ``ours``, ``failed`` on our side (not charged either)."""
    submission = _finish(session, claim, worker)
    if submission is None:
        return False
    submission.status = advance(
        submission.status,
        SubmissionStatus.failed if ours else SubmissionStatus.rejected,
        SUBMISSION_MOVES,
    )
    submission.status_reason = reason
    submission.failed_on_our_side = ours
    submission.finished_at = utcnow()
    return True


def reap(session: Session, service: ServiceSettings, *, queue_empty: bool) -> list[int]:
    """Validations to send again: those whose worker stopped renewing the lease, and, when the
    queue is empty, those whose task was lost before any worker held them."""
    moment = utcnow()
    resend: list[int] = []
    active = UploadValidation.finished_at.is_(None)
    for job in session.scalars(leases.expired(UploadValidation, active)):
        leases.drop(job)
        resend.append(job.submission_id)
    if queue_empty:
        idle = session.scalars(
            select(UploadValidation)
            .join(Submission)
            .where(
                active,
                UploadValidation.worker == "",
                Submission.status == SubmissionStatus.validating,
            )
            .with_for_update(of=UploadValidation)
        )
        for job in idle:
            if job.submission_id in resend:
                continue
            if job.lease_expires_at is None or job.lease_expires_at < moment:
                job.lease_expires_at = leases.lease_until(service)
                resend.append(job.submission_id)
    return resend


# A submission in one of these will never run again: its requirements' folder is freed.
DEPS_RELEASED = (
    SubmissionStatus.rejected,
    SubmissionStatus.cancelled,
    SubmissionStatus.disqualified,
)


def deps_in_use(session: Session) -> set[str]:
    """Requirement folders a submission that may still run names (a rejected, cancelled or
    disqualified one keeps none; a failed one may be re-run by an organiser)."""
    keys = session.scalars(
        select(Submission.deps_key).where(
            Submission.deps_key.is_not(None), Submission.status.not_in(DEPS_RELEASED)
        )
    )
    return set(keys)


def deps_released(session: Session) -> set[str]:
    """Requirement folders named by submissions that will never run again (maybe also by one
    that may: :func:`deps_in_use` decides)."""
    keys = session.scalars(
        select(Submission.deps_key).where(
            Submission.deps_key.is_not(None), Submission.status.in_(DEPS_RELEASED)
        )
    )
    return set(keys)
