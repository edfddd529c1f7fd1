"""Validating an upload, as database transitions: the API reserves the quota slot and stores the
zip (:func:`reserve`, :func:`stored`); a worker validates it in the sandbox and records the
verdict (:func:`record_valid`, which queues it, or :func:`record_rejected`, which gives the slot
back). A team has at most one upload ``validating`` (a unique partial index, migration 0010), so
parallel uploads cannot cost more intakes than the quota holds.
"""

from __future__ import annotations

import uuid
from datetime import timedelta

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from arena.config import Settings
from server.core.db import Database
from server.models import Submission, Team, utcnow
from server.services.errors import Conflict
from server.services.evaluation import lock
from server.status import SUBMISSION_MOVES, SubmissionStatus, advance

S = SubmissionStatus
BUSY = (
    "an upload of your team is still being validated: wait until it is queued or rejected "
    "(GET /api/v1/submissions/{id})"
)


def check_not_busy(session: Session, team_id: int) -> None:
    """Refuse early (before the body is read) when the team's slot is taken."""
    busy = session.scalar(
        select(Submission.id).where(
            Submission.team_id == team_id, Submission.status == S.validating
        )
    )
    if busy is not None:
        raise Conflict(BUSY.replace("{id}", str(busy)))


def reserve(db: Database, team_id: int, fields: dict, check_quota) -> tuple[int, str]:
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
                status=S.validating,
                **fields,
            )
            session.add(submission)
            session.flush()
            return submission.id, submission.upload_key
    except IntegrityError as exc:  # the partial unique index: another upload won the race
        raise Conflict(BUSY.replace("{id}", "")) from exc


def give_back(db: Database, submission_id: int) -> None:
    """The upload never passed its cheap checks: the reservation leaves no trace."""
    with db.session() as session:
        submission = session.get(Submission, submission_id)
        if submission is not None and submission.status == S.validating:
            session.delete(submission)


def stored(db: Database, submission_id: int, sha256: str, size: int) -> None:
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        submission.file_sha256, submission.file_size = sha256, size


def upload_of(session: Session, submission_id: int) -> Submission | None:
    """The submission to validate; None when it is no longer ``validating`` (a duplicate
    delivery, or cancelled meanwhile)."""
    submission = session.get(Submission, submission_id)
    if submission is None or submission.status != S.validating:
        return None
    return submission


def record_valid(
    session: Session, submission_id: int, *, deps_key: str | None, explanation: str | None
) -> bool:
    """Queue the validated submission; False when it is no longer ``validating``."""
    submission = lock(session, Submission, submission_id)
    if submission.status != S.validating:
        return False
    submission.status = advance(submission.status, S.queued, SUBMISSION_MOVES)
    submission.queued_at = utcnow()
    submission.deps_key = deps_key
    if not submission.description.strip():
        submission.description = (explanation or "").strip()
    return True


def record_rejected(session: Session, submission_id: int, reason: str, *, ours: bool) -> bool:
    """``rejected`` (the zip broke a rule: ``reason`` names it; the slot and the try are given
    back) or, with ``ours``, ``failed`` on our side. False when it is no longer validating."""
    submission = lock(session, Submission, submission_id)
    if submission.status != S.validating:
        return False
    new = S.failed if ours else S.rejected
    submission.status = advance(submission.status, new, SUBMISSION_MOVES)
    submission.status_reason = reason
    submission.failed_on_our_side = ours
    submission.finished_at = utcnow()
    return True


def stale(session: Session, settings: Settings) -> list[int]:
    """Uploads validating for longer than a validation can take: their task was lost."""
    cutoff = utcnow() - timedelta(seconds=4 * settings.intake_timeout_s + 60)
    return list(
        session.scalars(
            select(Submission.id).where(
                Submission.status == S.validating, Submission.created_at < cutoff
            )
        )
    )


def deps_in_use(session: Session) -> set[str]:
    """Requirement folders a kept submission names (rejected ones keep none)."""
    keys = session.scalars(
        select(Submission.deps_key).where(
            Submission.deps_key.is_not(None), Submission.status != S.rejected
        )
    )
    return set(keys)
