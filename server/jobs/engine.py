"""The job engine: every kind of sandboxed work a worker does goes through one life,

    claim -> heartbeat -> fence -> finish | hand back -> reap

written once here for all job kinds (an upload's validation, an episode of a scenario, a
training), after grand-challenge's ``ComponentJob``. This module is the worker half; the database
half, the same for every kind, is :mod:`server.jobs.leases` over the job's row
(:class:`~server.jobs.rows.LeasedJob`: worker, claim number, lease):

- **claim**: the Celery task names a job by its ids; the kind takes the job's row
  (:func:`~server.jobs.leases.claim`: the claim number goes up, the lease starts) or returns None
  when the job is over or held by a live lease (a duplicate delivery: nothing to do).
- **heartbeat**: while the job runs, the worker's one heartbeat thread
  (:mod:`server.jobs.heartbeat`) renews its lease, with the progress the job reports.
- **fence**: every write of the job goes through its claim number
  (:func:`~server.jobs.leases.fence`, :func:`~server.jobs.leases.owned`), so a claim that was
  superseded (its worker presumed dead) writes nothing; the heartbeat finding the claim gone
  stops the job.
- **finish**: the job's result is written through the fence (and follow-up tasks are sent after
  the transaction committed).
- **hand back**: a worker that stops (warm shutdown) releases the claim and sends the job again;
  a job whose claim was lost is dropped without a word.
- **our failures**: an :class:`~arena.errors.InfrastructureError` is retried (the claim released
  first) up to :data:`INFRASTRUCTURE_RETRIES` times; any other exception, exhausted retries, and
  a job whose workers died more than ``max_claims`` times end as a failure *on our side*
  (recorded, never charged to the team, and never re-sent forever).
- **reap**: :func:`reap_once` (the worker's reaper thread) asks every kind for jobs whose lease
  expired, or whose task was lost before anyone took it (:func:`~server.jobs.leases.reap`), and
  sends them again.

Adding a job kind costs a table and its transitions:

1. A table mixing in :class:`~server.jobs.rows.LeasedJob` and saying when its job is
   ``under_way`` (a hybrid property, 3 lines), with its Alembic migration; in its service, the
   claim object the worker gets (with its ``claim_number``) and the transitions: claim (lock the
   row, check its state, :func:`~server.jobs.leases.claim`), fence, renew, release, the finish
   guard and reap, each a call into :mod:`server.jobs.leases` plus what is the kind's own, and
   the writes of its results. Measured on the three kinds (lines of those functions and the
   claim object, docstrings included): 70 for the training, 88 for the validation (its time
   budget is charged per claim), 150 for the episode (its claim also makes the row and checks
   the suite, its reap also re-sends whole runs and queued submissions); 96, 111 and 160 when
   each wrote its own claim, fence, guard and reap.
2. A class satisfying :class:`~server.jobs.kind.JobKind` (see :mod:`server.worker.trainings`):
   claim, renew, release, send_again and reap are calls of those service functions (25, 29 and
   38 lines in the three kinds), plus ``run`` (the sandboxed work; call ``lease.stop_with(...)``
   to be killable from outside and ``lease.report(...)`` to show progress), ``ours`` and
   ``finish``.
3. A task name in :mod:`server.core.celery_app`, a ``TaskQueue`` method that sends it, and in
   :mod:`server.worker.tasks` a task ``run_job(KIND, self, get_settings(), local.worker(),
   <ids>)`` declared with ``arena_task`` (``bind=True``,
   ``max_retries=INFRASTRUCTURE_RETRIES``), with the kind added to ``JOB_KINDS`` (the reaper's
   list): about 10 lines.

The engine and the heartbeat import nothing of :mod:`server.worker`: the worker process's name,
database and queue come in as a :class:`~server.jobs.kind.Worker` from its composition root
(:mod:`server.worker.local`).
"""

from __future__ import annotations

import logging
import traceback
from typing import Any

from celery import Task

from arena.config import ServiceSettings, Settings
from arena.errors import InfrastructureError
from server.core.queue import BROKER_ERRORS, TaskQueue
from server.jobs.heartbeat import heartbeat
from server.jobs.kind import JobKind, Worker

log = logging.getLogger(__name__)

INFRASTRUCTURE_RETRIES = 2
# [s] Wait before retry n (1, 2, ...): n times this.
RETRY_BACKOFF_S = 10
# The failure of a job every worker that took it died with.
WORKER_LOST = "worker_lost"


def run_job(kind: JobKind, task: Task, settings: Settings, worker: Worker, **ids: Any) -> None:
    """The whole life of one job in the Celery ``task`` (bound) that names it by ``ids``, run by
    ``worker``."""
    with worker.database.session() as session:
        claim = kind.claim(session, settings, worker.name, **ids)
    if claim is None:
        return
    if claim.claim_number > kind.max_claims:
        # Every worker that took this job died with it (or was killed): stop handing it out.
        died = f"{claim.claim_number - 1} workers died holding it"
        kind.finish(claim, worker.name, kind.ours(claim, WORKER_LOST, died), settings)
        return
    try:
        with heartbeat().hold(kind, claim, worker, settings.service) as lease:
            result = kind.run(claim, lease, settings)
    except InfrastructureError as exc:
        if task.request.retries < INFRASTRUCTURE_RETRIES:
            with worker.database.session() as session:
                kind.release(session, claim, worker.name)
            countdown = RETRY_BACKOFF_S * (task.request.retries + 1)
            raise task.retry(exc=exc, countdown=countdown) from exc
        result = kind.ours(claim, type(exc).__name__, str(exc))
    except Exception as exc:
        # A bug on our side: recorded (the team sees a failure that is not theirs, an organiser
        # can run it again) rather than left for the reaper to hand out again and again.
        log.exception("%s %s crashed the task", kind.name, claim)
        result = kind.ours(claim, type(exc).__name__, traceback.format_exc())
    else:
        if lease.handed_back.is_set():
            # Cut short on purpose: whatever it returned is not the team's result.
            hand_back(kind, claim, worker)
            return
        if lease.lost.is_set() or result is None:
            return  # cancelled, or another worker has it: its writes would be fenced off
    kind.finish(claim, worker.name, result, settings)


def hand_back(kind: JobKind, claim: Any, worker: Worker) -> None:
    """This worker is stopping: release the claim and send the job again for another worker."""
    with worker.database.session() as session:
        released = kind.release(session, claim, worker.name)
    if released:
        kind.send_again(worker.queue, claim)
        log.warning("handed %s %s back", kind.name, claim)


def reap_once(
    kinds: tuple[JobKind, ...], service: ServiceSettings, queue: TaskQueue
) -> dict[str, int]:
    """Send again every kind's jobs whose lease expired, through ``queue``; how many, per kind."""
    try:
        queue_empty = queue.depth() == 0
    except BROKER_ERRORS as exc:
        log.warning("reaper cannot read the queue: %s", exc)
        return {}
    resent = {kind.name: kind.reap(service, queue, queue_empty=queue_empty) for kind in kinds}
    if any(resent.values()):
        log.warning(
            "reaper re-sent %s", ", ".join(f"{n} {name}(s)" for name, n in resent.items() if n)
        )
    return resent
