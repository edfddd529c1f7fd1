"""Claims and leases of a job row, the same for every job kind (an episode, a training, ...).

A leased row carries ``worker`` (who holds it; empty when nobody does), ``lease_expires_at`` and a
claim counter (the fence token). A worker *takes* the row (:func:`take`: the counter goes up, the
lease starts), *renews* the lease while it works (:func:`renew`), and every later write goes
through the fence: the row's key plus "still running, still this worker, still this claim
number", so a worker presumed dead can never write over the one that took its job over.
:func:`release` hands the row back; :func:`expired` selects the rows whose worker stopped renewing.

The worker side of the same life (one heartbeat thread, hand back, reaper) is
:mod:`server.worker.engine`.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any, Protocol

from sqlalchemy import Select, select, update
from sqlalchemy.orm import Session

from arena.config import ServiceSettings
from server.models import utcnow as now


class LeasedRow(Protocol):
    worker: str
    lease_expires_at: datetime | None


# What a kind's renew answers when the job is still its worker's but should let another run
# first: the heartbeat hands it back (released and sent again, server/worker/engine.py).
HAND_BACK = "hand back"


def lease_until(service: ServiceSettings) -> datetime:
    return now() + timedelta(seconds=service.lease_seconds)


def alive(lease_expires_at: datetime | None) -> bool:
    return lease_expires_at is not None and lease_expires_at > now()


def held(row: LeasedRow) -> bool:
    """Held by a worker whose lease is still valid: not to be claimed."""
    return bool(row.worker) and alive(row.lease_expires_at)


def take(row: LeasedRow, worker: str, service: ServiceSettings) -> None:
    """``worker`` holds the row from now on (the caller counts the claim)."""
    row.worker = worker
    row.lease_expires_at = lease_until(service)


def drop(row: LeasedRow) -> None:
    """Nobody holds the row: the reaper, a cancel or the end of the job let it go."""
    row.worker = ""
    row.lease_expires_at = None


def renew(
    session: Session, service: ServiceSettings, model: type, fence: tuple, **values: Any
) -> bool:
    """Extend the lease of the row behind ``fence`` (and write ``values`` with it); False when
    the claim is no longer the caller's: its job must stop, its result would be refused."""
    renewed = session.execute(
        update(model).where(*fence).values(lease_expires_at=lease_until(service), **values)
    )
    return renewed.rowcount == 1


def release(session: Session, model: type, fence: tuple) -> bool:
    """Hand the row behind ``fence`` back (its worker is stopping, or retries later): any worker
    may claim it at once. False when the claim was no longer the caller's."""
    released = session.execute(update(model).where(*fence).values(worker="", lease_expires_at=None))
    return released.rowcount == 1


def expired(model: Any, *running: Any) -> Select:
    """Rows in a ``running`` state whose worker stopped renewing the lease, locked."""
    return (
        select(model)
        .where(*running, model.worker != "", model.lease_expires_at < now())
        .with_for_update()
    )
