"""Claims and leases of a job's row (:class:`~server.jobs.rows.LeasedJob`), the same for every
job kind: the database half of the engine (:mod:`server.jobs.engine` is the worker half).

A worker *claims* the row (:func:`claim`: the claim number goes up, the lease starts), *renews*
the lease while it works (:func:`renew`), and every later write goes through the :func:`fence`:
the row's key plus "still under way, still this worker, still this claim number", so a worker
presumed dead can never write over the one that took its job over; a result written from the
row itself is checked the same way first (:func:`owned`). :func:`release` hands the row back;
:func:`reap` releases the rows whose worker stopped renewing and finds those whose task was lost
before anyone held them.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any, Protocol, TypeVar

from sqlalchemy import Select, select, update
from sqlalchemy.orm import Session

from arena.config import ServiceSettings
from server.jobs.rows import LeasedJob
from server.models import utcnow as now

RowT = TypeVar("RowT")
JobT = TypeVar("JobT", bound=LeasedJob)


class LeasedRow(Protocol):
    """Any row a worker leases: a job, or an evaluation run (renewed with its episodes)."""

    worker: str
    lease_expires_at: datetime | None


def lease_until(service: ServiceSettings) -> datetime:
    return now() + timedelta(seconds=service.lease_seconds)


def alive(lease_expires_at: datetime | None) -> bool:
    return lease_expires_at is not None and lease_expires_at > now()


def held(row: LeasedRow) -> bool:
    """Held by a worker whose lease is still valid: not to be claimed."""
    return bool(row.worker) and alive(row.lease_expires_at)


def locked(session: Session, model: type[RowT], *where: Any) -> RowT | None:
    """The row of ``model`` matching ``where``, locked until the transaction ends, and read as
    it is once locked, not as this session first read it: a stale "not held" let two workers
    claim one validation."""
    return session.scalar(
        select(model).where(*where).with_for_update().execution_options(populate_existing=True)
    )


def take(row: LeasedRow, worker: str, service: ServiceSettings) -> None:
    """``worker`` holds the row from now on."""
    row.worker = worker
    row.lease_expires_at = lease_until(service)


def claim(job: LeasedJob, worker: str, service: ServiceSettings) -> int | None:
    """``worker`` claims the (locked) job: its new claim number, the fence token of every write
    it makes; None when a worker whose lease is still valid holds it."""
    if held(job):
        return None
    job.claim_number += 1
    take(job, worker, service)
    return job.claim_number


def drop(row: LeasedRow) -> None:
    """Nobody holds the row: the reaper, a cancel or the end of the job let it go."""
    row.worker = ""
    row.lease_expires_at = None


def fence(model: type[LeasedJob], worker: str, claim_number: int, *key: Any) -> tuple:
    """The row ``key`` names, as long as it is ``worker``'s claim number ``claim_number`` and
    under way: what every write of the job goes through."""
    return (
        *key,
        model.under_way,
        model.worker == worker,
        model.claim_number == claim_number,
    )


def owned(job: LeasedJob, worker: str, claim_number: int) -> bool:
    """Whether the (locked) job is still under way as ``worker``'s claim ``claim_number``: a
    duplicate delivery or a superseded claim must not write its result."""
    return bool(job.under_way) and (job.worker, job.claim_number) == (worker, claim_number)


def renew(
    session: Session, service: ServiceSettings, model: type, fence: tuple, **values: Any
) -> bool:
    """Extend the lease of the row behind ``fence`` (and write ``values`` with it); False when
    the claim is no longer the caller's: its job must stop, its result would be refused."""
    renewed = session.execute(
        update(model).where(*fence).values(lease_expires_at=lease_until(service), **values)
    )
    return renewed.rowcount == 1


def release(session: Session, model: type[LeasedJob], fence: tuple) -> bool:
    """Hand the row behind ``fence`` back (its worker is stopping, or retries later): any worker
    may claim it at once. False when the claim was no longer the caller's."""
    released = session.execute(update(model).where(*fence).values(worker="", lease_expires_at=None))
    return released.rowcount == 1


def expired(model: type[JobT]) -> Select[tuple[JobT]]:
    """Jobs under way whose worker stopped renewing the lease, locked (narrow it further)."""
    return (
        select(model)
        .where(model.under_way, model.worker != "", model.lease_expires_at < now())
        .with_for_update()
    )


def unheld(model: type[JobT]) -> Select[tuple[JobT]]:
    """Jobs no worker holds, locked (narrow it to those still waiting to run)."""
    return select(model).where(model.worker == "").with_for_update(of=model)


def reap(
    session: Session,
    service: ServiceSettings,
    expired: Select[tuple[JobT]],
    waiting: Select[tuple[JobT]] | None,
) -> tuple[list[JobT], list[JobT]]:
    """The jobs to send again: those of ``expired`` (released at once: the re-sent task claims
    them, the old claim's writes are fenced off), and, given ``waiting`` (when the queue is
    empty), those whose lease, set when their task was sent, ran out before any worker took
    them: their task was lost (the lease starts again with the re-sent one)."""
    stale = list(session.scalars(expired))
    for job in stale:
        drop(job)
    lost: list[JobT] = []
    if waiting is not None:
        for job in session.scalars(waiting):
            if job not in stale and not alive(job.lease_expires_at):
                job.lease_expires_at = lease_until(service)
                lost.append(job)
    return stale, lost
