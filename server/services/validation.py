"""Validating an upload, as database transitions: the API reserves the quota slot and stores the
zip (:func:`reserve`, :func:`stored`); a worker claims the validation job (:func:`claim`, leased
like every job of the engine, :mod:`server.jobs.leases`), validates the zip in the sandbox and
records the verdict through the fence (:func:`record_valid`, which queues the submission, or
:func:`record_rejected`, which gives its quota try back).

A team has at most one upload ``validating`` (a unique partial index, migration 0010), so parallel
uploads cannot cost more intakes than one at a time, and none beyond the quota.

Validation time is the team's, fairly shared (migration 0017): every claim of a validation is
charged the worker time it held (``used_s``; a dead worker's is ours), whatever the verdict, to
the team's daily budget (``ARENA_VALIDATION_BUDGET_S``): a validation runs at most what is left,
and a team past it cannot upload until the next UTC day. A validation task is a token: it claims
the waiting validation of the team that has used the least validation time today (the oldest
among equals), not the one it names, and a validation that has run for a slice
(``ARENA_VALIDATION_SLICE_S``) while a team that used less waits yields its worker (handed back,
sent again: :data:`server.jobs.kind.HAND_BACK`). So one team's validations never hold up
another's for more than a slice.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, time

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from arena.config import IntakeSettings, ServiceSettings
from server.core.db import Database
from server.jobs import leases
from server.jobs.kind import HAND_BACK
from server.models import Submission, Team, UploadValidation, utcnow
from server.services.errors import Conflict, QuotaExceeded
from server.services.evaluation import end_submission, lock
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
    # [s] What this claim may run: the intake's timeout, or what is left of the team's budget
    # today (0: nothing left, rejected without running).
    time_budget_s: float = 0.0
    slice_s: float = 0.0  # [s] after which it yields to a team that used less today


def used_today(session: Session, team_id: int, moment: datetime) -> float:
    """Validation time [s] the team's uploads used since the UTC day began (a claim under way
    counted up to ``moment``)."""
    day_start = datetime.combine(moment.date(), time.min, tzinfo=moment.tzinfo)
    rows = session.execute(
        select(UploadValidation.used_s, UploadValidation.claimed_at)
        .join(Submission, Submission.id == UploadValidation.submission_id)
        .where(Submission.team_id == team_id, UploadValidation.created_at >= day_start)
    ).all()
    return sum(used + _running_s(claimed, moment) for used, claimed in rows)


def _running_s(claimed_at: datetime | None, moment: datetime) -> float:
    return max(0.0, (moment - claimed_at).total_seconds()) if claimed_at is not None else 0.0


def check_budget(session: Session, intake: IntakeSettings, team_id: int) -> None:
    """Refuse an upload once the team's validations used its validation time today."""
    used = used_today(session, team_id, utcnow())
    if used >= intake.validation_budget_s:
        raise QuotaExceeded(
            f"your team's uploads used {used:.0f} s of validation time today, its budget of "
            f"{intake.validation_budget_s:g} s (every validation is charged the time it took, "
            "rejected ones too): upload again after 00:00 UTC, and check zips locally first "
            "(arena submission check)"
        )


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
                    claim_number=0,
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
    # Read as locked, not as fair_order first read it (leases.locked).
    return leases.locked(session, UploadValidation, UploadValidation.submission_id == submission_id)


def _waiting(session: Session) -> list[UploadValidation]:
    """Validations no live claim holds, of submissions still validating."""
    jobs = session.scalars(
        select(UploadValidation)
        .join(Submission, Submission.id == UploadValidation.submission_id)
        .where(
            UploadValidation.finished_at.is_(None),
            Submission.status == SubmissionStatus.validating,
        )
    ).all()
    return [job for job in jobs if not leases.held(job)]


def fair_order(session: Session, jobs: list[UploadValidation]) -> list[UploadValidation]:
    """``jobs`` by their team's validation time today, then age: the next to run first."""
    moment = utcnow()
    teams = {job.submission.team_id for job in jobs}
    used = {team: used_today(session, team, moment) for team in teams}
    return sorted(jobs, key=lambda job: (used[job.submission.team_id], job.created_at, job.id))


def claim(
    session: Session, service: ServiceSettings, intake: IntakeSettings, worker: str
) -> ValidationClaim | None:
    """Take, for ``worker``, the waiting validation that is fairest to run next (a task is a
    token, whichever upload sent it); None when none waits unheld."""
    for candidate in fair_order(session, _waiting(session)):
        submission = lock(session, Submission, candidate.submission_id)
        job = _job(session, candidate.submission_id)
        if job is None or submission.status != SubmissionStatus.validating:
            continue
        claim_number = leases.claim(job, worker, service)
        if claim_number is None:
            continue  # another worker took it meanwhile
        moment = utcnow()
        left = intake.validation_budget_s - used_today(session, submission.team_id, moment)
        job.started_at = job.started_at or moment
        job.claimed_at = moment
        return ValidationClaim(
            submission_id=submission.id,
            upload_key=submission.upload_key,
            needs_training=submission.track == Track.offline,
            claim_number=claim_number,
            time_budget_s=max(0.0, min(intake.intake_timeout_s, left)),
            slice_s=intake.validation_slice_s,
        )
    return None


def _charge(job: UploadValidation) -> None:
    """The claim ends: the time it held its worker is added to what the team used."""
    job.used_s += _running_s(job.claimed_at, utcnow())
    job.claimed_at = None


def should_yield(session: Session, claim: ValidationClaim) -> bool:
    """The claim has run a slice and a validation of a team that used less today waits."""
    job = session.get(UploadValidation, _job_id(session, claim.submission_id))
    if job is None or _running_s(job.claimed_at, utcnow()) < claim.slice_s:
        return False
    ours = job.submission.team_id
    others = [other for other in _waiting(session) if other.submission.team_id != ours]
    if not others:
        return False
    moment = utcnow()
    mine = used_today(session, ours, moment)
    return any(used_today(session, o.submission.team_id, moment) < mine for o in others)


def _job_id(session: Session, submission_id: int) -> int | None:
    return session.scalar(
        select(UploadValidation.id).where(UploadValidation.submission_id == submission_id)
    )


def _fence(claim: ValidationClaim, worker: str) -> tuple:
    key = UploadValidation.submission_id == claim.submission_id
    return leases.fence(UploadValidation, worker, claim.claim_number, key)


def renew(
    session: Session, service: ServiceSettings, claim: ValidationClaim, worker: str
) -> bool | str:
    """Extend the lease; False when the claim is no longer ours, :data:`HAND_BACK` when it should
    yield its worker to a fairer validation."""
    if not leases.renew(session, service, UploadValidation, _fence(claim, worker)):
        return False
    return HAND_BACK if should_yield(session, claim) else True


def release(session: Session, claim: ValidationClaim, worker: str) -> bool:
    """Hand the claim back (its run has ended): charged what it used, and not counted as a
    claim a worker died with (``max_claims``), so a validation that yields its worker again and
    again is not taken for one that kills workers. Its claim number is free again: the run
    that held it is over."""
    job = leases.locked(session, UploadValidation, *_fence(claim, worker))
    if job is None:
        return False
    _charge(job)
    leases.drop(job)
    job.claim_number -= 1
    return True


def _finish(session: Session, claim: ValidationClaim, worker: str) -> Submission | None:
    """The submission, when the claim is still ``worker``'s and it is still validating."""
    submission = lock(session, Submission, claim.submission_id)
    job = _job(session, claim.submission_id)
    if job is None or not leases.owned(job, worker, claim.claim_number):
        return None
    _charge(job)
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
    status = SubmissionStatus.failed if ours else SubmissionStatus.rejected
    end_submission(submission, reason, ours=ours, status=status)
    return True


def reap(session: Session, service: ServiceSettings, *, queue_empty: bool) -> list[int]:
    """Validations to send again: those whose worker stopped renewing the lease, and, when the
    queue is empty, those whose task was lost before any worker held them."""
    waiting = (
        leases.unheld(UploadValidation)
        .join(Submission)
        .where(UploadValidation.under_way, Submission.status == SubmissionStatus.validating)
    )
    stale, lost = leases.reap(
        session, service, leases.expired(UploadValidation), waiting if queue_empty else None
    )
    for job in stale:
        job.claimed_at = None  # its worker died: that time is ours, not the team's
    return [job.submission_id for job in stale + lost]


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


def deps_by_team(session: Session) -> dict[int, set[str]]:
    """The requirement folders of each team's submissions that may still run."""
    rows = session.execute(
        select(Submission.team_id, Submission.deps_key).where(
            Submission.deps_key.is_not(None), Submission.status.not_in(DEPS_RELEASED)
        )
    )
    teams: dict[int, set[str]] = {}
    for team_id, key in rows:
        teams.setdefault(team_id, set()).add(key)
    return teams


def deps_released(session: Session) -> set[str]:
    """Requirement folders named by submissions that will never run again (maybe also by one
    that may: :func:`deps_in_use` decides)."""
    keys = session.scalars(
        select(Submission.deps_key).where(
            Submission.deps_key.is_not(None), Submission.status.in_(DEPS_RELEASED)
        )
    )
    return set(keys)
