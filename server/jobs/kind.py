"""What the job engine and the heartbeat share: :class:`JobKind`, one kind of sandboxed job
(:mod:`server.jobs.engine` runs every kind through one life), :class:`Lease`, one claim a
worker holds while its job runs (:mod:`server.jobs.heartbeat` renews it), and :class:`Worker`,
the process it runs in."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from sqlalchemy.orm import Session

from arena.config import ServiceSettings, Settings
from server.core.db import Database
from server.core.queue import TaskQueue


@dataclass(frozen=True)
class Worker:
    """The worker process a job runs in, as the engine needs it: handed in by the process's
    composition root (:mod:`server.worker.local`), so that the engine depends on no worker."""

    name: str  # what claims name their holder by: ``host:pid``
    database: Database
    queue: TaskQueue


class Claim(Protocol):
    """What a kind's claim returns: whatever its worker needs, with the fence token."""

    @property
    def claim_number(self) -> int: ...


ClaimT = TypeVar("ClaimT", bound=Claim)
ResultT = TypeVar("ResultT")

# What a kind's renew answers when the job is still its worker's but should let another run
# first: the heartbeat hands it back (released and sent again: server/jobs/engine.py hand_back).
HAND_BACK = "hand back"


class JobKind(Protocol[ClaimT, ResultT]):
    """One kind of job: how to claim, renew, release, run, finish and reap it."""

    name: str  # in logs: "episode", "training"
    max_claims: int  # claims of one job (workers dying with it) before it fails as ours

    def claim(self, session: Session, settings: Settings, worker: str, **ids: Any) -> ClaimT | None:
        """Take the job for ``worker``; None when it is over or held by a live lease. (The whole
        settings here and in ``run`` and ``finish``: each kind needs other groups.)"""

    def renew(
        self,
        session: Session,
        service: ServiceSettings,
        claim: ClaimT,
        worker: str,
        **progress: Any,
    ) -> bool | str:
        """Extend the lease (writing the progress); False when the claim is no longer ours,
        :data:`HAND_BACK` when it should let another job run first."""

    def release(self, session: Session, claim: ClaimT, worker: str) -> bool:
        """Hand the job back: any worker may claim it at once. False when no longer ours."""

    def send_again(self, queue: TaskQueue, claim: ClaimT) -> None:
        """Send the job's task again (after a release)."""

    def run(self, claim: ClaimT, lease: Lease, settings: Settings) -> ResultT | None:
        """Do the work. Returns None only when it stopped because ``lease.stopped``."""

    def ours(self, claim: ClaimT, reason: str, error: str) -> ResultT:
        """The result of a job that failed on our side (not charged to the team)."""

    def finish(self, claim: ClaimT, worker: str, result: ResultT, settings: Settings) -> None:
        """Write the result through the fence, then send any follow-up task."""

    def reap(self, service: ServiceSettings, queue: TaskQueue, *, queue_empty: bool) -> int:
        """Send again the jobs whose lease expired (and, when the queue is empty, those whose
        task was lost before any worker held them); how many."""


@dataclass(eq=False)
class Lease:
    """One claim a worker holds while its job runs."""

    kind: JobKind
    claim: Any
    worker: str
    lost: threading.Event = field(default_factory=threading.Event)
    handed_back: threading.Event = field(default_factory=threading.Event)
    progress: dict[str, Any] = field(default_factory=dict)
    _on_stop: Callable[[], None] | None = None

    @property
    def stopped(self) -> bool:
        return self.lost.is_set() or self.handed_back.is_set()

    def stop_with(self, hook: Callable[[], None]) -> None:
        """What ends the job from outside when its lease is lost or handed back (it may run
        several times: until the job returns, nothing it starts may outlive the claim)."""
        self._on_stop = hook

    def report(self, **progress: Any) -> bool:
        """Progress written with the next renewal; False once the job must stop."""
        self.progress = progress
        return not self.stopped

    def stop(self) -> None:
        if self._on_stop is not None:
            self._on_stop()
