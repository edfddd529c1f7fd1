"""The worker's one heartbeat: a single thread that renews the lease of every job the worker
process holds (whatever its kind), and stops the jobs whose claim is gone.

A job is held through :meth:`Heartbeat.hold`, which returns its :class:`Lease`. Each round (every
third of the lease, at most 5 s apart) the thread renews every lease through its kind's
``renew``, writing the progress the job last reported (:meth:`Lease.report`). When a renewal
finds the claim gone (the job was cancelled, or the reaper gave it to another worker) the lease
is *lost*; when the worker begins a warm shutdown (:data:`shutting_down`) every lease is *handed
back*. Either way the job's stop hook runs (e.g. killing its sandbox) and :attr:`Lease.stopped`
turns true, so the job ends at once; :mod:`server.jobs.engine` then drops its result or hands
the job to another worker.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from arena.config import ServiceSettings
from server.core.db import Database
from server.jobs.kind import HAND_BACK, JobKind, Lease, Worker

log = logging.getLogger(__name__)

# Set when the worker begins a warm shutdown (SIGTERM): every job it holds is handed back.
shutting_down = threading.Event()
# [s] How often the thread looks at shutdown and lost leases between renewals.
TICK_S = 0.2


def beat_interval_s(lease_seconds: float) -> float:
    """[s] Renewals three times per lease, at most 5 s apart (the pace progress is shown at)."""
    return min(max(lease_seconds / 3, 0.5), 5.0)


class Heartbeat:
    """The renewing thread of one worker process, started with the first lease it holds."""

    def __init__(self) -> None:
        self._leases: set[Lease] = set()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    @contextmanager
    def hold(
        self, kind: JobKind, claim: Any, worker: Worker, service: ServiceSettings
    ) -> Iterator[Lease]:
        """``service``: the lease's settings; the thread, started with the process's first lease,
        keeps them and the worker's database (a process has one configuration)."""
        lease = Lease(kind, claim, worker.name)
        with self._lock:
            self._leases.add(lease)
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run,
                    args=(service, worker.database),
                    name="arena-heartbeat",
                    daemon=True,
                )
                self._thread.start()
        try:
            yield lease
        finally:
            with self._lock:
                self._leases.discard(lease)

    def _held(self) -> list[Lease]:
        with self._lock:
            return list(self._leases)

    def _run(self, service: ServiceSettings, database: Database) -> None:
        interval = beat_interval_s(service.lease_seconds)
        next_beat = time.monotonic() + interval
        while True:
            time.sleep(TICK_S)
            if shutting_down.is_set():
                for lease in self._held():
                    lease.handed_back.set()
                    lease.stop()
                continue
            if time.monotonic() < next_beat:
                continue
            next_beat += interval
            for lease in self._held():
                if not lease.lost.is_set():
                    self._renew(lease, service, database)

    @staticmethod
    def _renew(lease: Lease, service: ServiceSettings, database: Database) -> None:
        try:
            with database.session() as session:
                active = lease.kind.renew(
                    session, service, lease.claim, lease.worker, **lease.progress
                )
        except SQLAlchemyError as exc:
            # The database is briefly away: the lease has time left, the next round tries again.
            log.warning("lease heartbeat of %s %s failed: %s", lease.kind.name, lease.claim, exc)
            return
        if active == HAND_BACK:
            lease.handed_back.set()
            lease.stop()
        elif not active:
            lease.lost.set()
            lease.stop()


@lru_cache(maxsize=1)
def heartbeat() -> Heartbeat:
    """This worker process's heartbeat (cleared in a forked child: threads do not survive fork)."""
    return Heartbeat()
