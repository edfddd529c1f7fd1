"""Celery tasks of the service: thin wrappers around :mod:`server.services.evaluation`.

Every task is declared with :func:`arena_task` (late acknowledgement, requeue when the worker
process dies, one queue, time limits), takes keyword-only ids, returns early when the database
says its work is done, and sends follow-up tasks only after its transaction committed. Any task
can therefore be delivered twice: the unique (run, scenario) row makes the second a no-op.

``evaluate_submission`` fans out one ``run_scenario`` per scenario; the ``run_scenario`` that
finishes the last one sends ``aggregate_run``, which scores the run from its stored records.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import traceback
from contextlib import contextmanager
from dataclasses import asdict
from functools import lru_cache
from pathlib import Path
from typing import Any

from celery import shared_task
from celery.signals import worker_process_init, worker_ready, worker_shutdown
from sqlalchemy.exc import SQLAlchemyError

from arena.config import get_settings
from evaluator.celery_app import QUEUE, TASK_AGGREGATE, TASK_EVALUATE, TASK_SCENARIO
from evaluator.errors import InfrastructureError
from server.core.db import get_database
from server.services import evaluation, scoring
from server.services.admin import send_plan
from server.services.queue import BROKER_ERRORS, TaskQueue

log = logging.getLogger(__name__)

# [s] One scenario: agent start-up plus the episode limit (600 s) plus a SUMO retry.
SCENARIO_TIME_LIMIT_S = 1800
BOOKKEEPING_TIME_LIMIT_S = 300
INFRASTRUCTURE_RETRIES = 2
# Claims of one scenario (a worker dying mid-scenario releases its claim) before giving up.
MAX_SCENARIO_ATTEMPTS = 3


def arena_task(name: str, *, time_limit: int, **options: Any):
    """The one decorator for service tasks."""
    return shared_task(
        name=name,
        queue=QUEUE,
        acks_late=True,
        reject_on_worker_lost=True,
        time_limit=time_limit,
        soft_time_limit=time_limit - 30,
        ignore_result=True,
        **options,
    )


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@lru_cache(maxsize=1)
def _queue() -> TaskQueue:
    return TaskQueue(get_settings())


@arena_task(TASK_EVALUATE, time_limit=BOOKKEEPING_TIME_LIMIT_S)
def evaluate_submission(*, submission_id: int) -> None:
    with get_database().session() as session:
        plan = evaluation.start_evaluation(session, get_settings(), submission_id)
    if plan is not None:
        send_plan(_queue(), plan)


@arena_task(
    TASK_SCENARIO,
    time_limit=SCENARIO_TIME_LIMIT_S,
    bind=True,
    max_retries=INFRASTRUCTURE_RETRIES,
)
def run_scenario(self, *, run_id: int, scenario_id: str) -> None:
    settings = get_settings()
    db = get_database()
    me = worker_name()
    with db.session() as session:
        job = evaluation.claim_scenario(session, settings, run_id, scenario_id, me)
    if job is None:
        return
    if job.attempt > MAX_SCENARIO_ATTEMPTS:
        # Every worker that took this scenario died with it (or was killed): stop handing it out.
        outcome = _our_failure(job, "worker_lost", f"{job.attempt - 1} workers died running it")
    else:
        try:
            run_key = _run_key(job)
            with _heartbeat(run_id, me, labels=_sandbox_labels(run_key)):
                outcome = _simulate(job, run_key)
        except InfrastructureError as exc:
            if self.request.retries < INFRASTRUCTURE_RETRIES:
                raise self.retry(exc=exc, countdown=10 * (self.request.retries + 1)) from exc
            outcome = _our_failure(job, type(exc).__name__, str(exc))
        except Exception as exc:
            # A bug on our side: recorded (the run then fails visibly and can be re-run) rather
            # than left for the reaper to hand out again and again.
            log.exception("scenario %s of run %s crashed the task", scenario_id, run_id)
            outcome = _our_failure(job, type(exc).__name__, traceback.format_exc())
    with db.session() as session:
        last = evaluation.record_scenario(session, run_id, outcome)
    if last:
        _queue().aggregate(run_id)


@arena_task(TASK_AGGREGATE, time_limit=BOOKKEEPING_TIME_LIMIT_S)
def aggregate_run(*, run_id: int) -> None:
    with get_database().session() as session:
        evaluation.finish_run(session, run_id)


def _our_failure(
    job: evaluation.ScenarioJob, reason: str, error: str
) -> evaluation.ScenarioOutcomeIn:
    """A scenario that could not be evaluated through no fault of the submission."""
    return evaluation.ScenarioOutcomeIn(
        scenario_id=job.scenario_id,
        status=scoring.INFRASTRUCTURE_ERROR,
        reason=reason,
        detail={"error": error, "attempt": job.attempt},
    )


def _simulate(job: evaluation.ScenarioJob, run_key: str) -> evaluation.ScenarioOutcomeIn:
    from evaluator.runner import run_scenario as run_one
    from evaluator.summary import ScenarioStatus

    settings = get_settings()
    records = settings.resolved_data_dir / "runs" / str(job.run_id) / "records"
    outcome = run_one(
        _prepared(job.storage_dir),
        Path(job.scenario_dir),
        records,
        sandbox=_sandbox_kind(),
        run_key=run_key,
    )
    # The team sees this text: the hidden scenario's id must not appear in it.
    log_text = outcome.log.replace(job.scenario_id, "<scenario>")
    tail = log_text.encode()[-settings.agent_log_tail_bytes :].decode("utf-8", "replace")
    detail = {
        "agents": [asdict(agent) for agent in outcome.agents],
        "attempts": outcome.attempts,
        "wall_time_s": outcome.wall_time_s,
        "error": outcome.error,
    }
    common = {
        "scenario_id": job.scenario_id,
        "steps": outcome.steps,
        "log_tail": tail,
        "detail": detail,
    }
    if outcome.status == ScenarioStatus.simulator_error:
        return evaluation.ScenarioOutcomeIn(
            status=scoring.SIMULATOR_ERROR, reason="simulator_error", **common
        )
    if outcome.status != ScenarioStatus.done:
        return evaluation.ScenarioOutcomeIn(
            status=scoring.INFRASTRUCTURE_ERROR, reason=str(outcome.status), **common
        )
    failed = [agent for agent in outcome.agents if not agent.reached_goal]
    return evaluation.ScenarioOutcomeIn(
        status=scoring.FAILURE if failed else scoring.SUCCESS,
        reason=failed[0].reason if failed else "reached_goal",
        record_path=str(outcome.record_path) if outcome.record_path else None,
        **common,
    )


_prepare_lock = threading.Lock()


def _prepared(storage_dir: str):
    """One preparation per submission and worker process, even with several threads asking."""
    with _prepare_lock:
        return _prepare(storage_dir)


@lru_cache(maxsize=4)
def _prepare(storage_dir: str):
    """The submission ready to run, prepared once per worker process from the stored zip (so a
    worker on another machine needs only the shared data volume). Under the data dir, not a
    private temporary folder: the sandbox user must be able to enter it."""
    from submissions.intake import prepare_submission

    settings = get_settings()
    # No ':' in the name: Docker's volume syntax would split the path there.
    folder = f"{Path(storage_dir).name}-{socket.gethostname()}-{os.getpid()}"
    dest = settings.resolved_data_dir / "prepared" / folder
    return prepare_submission(Path(storage_dir) / "upload.zip", dest, settings)


@lru_cache(maxsize=1)
def _sandbox_kind():
    from evaluator import sandbox

    return sandbox.check_service_kind(settings=get_settings())


def _run_key(job: evaluation.ScenarioJob) -> str:
    # Per run, scenario claim and a random part: two submissions of the same zip (or two claims
    # of one scenario) never share sandbox labels, and nothing in it names the scenario.
    from evaluator.runner import new_run_key

    return f"r{job.run_id}a{job.attempt}-{new_run_key()}"


def _sandbox_labels(run_key: str) -> dict[str, str]:
    # The labels every attempt of the runner's sandboxes carries (evaluator.runner.scenario).
    from evaluator.runner import sandbox_labels

    return sandbox_labels(run_key)


@contextmanager
def _heartbeat(run_id: int, worker: str, labels: dict[str, str]):
    """Renew the run's lease while the scenario runs; when the run is cancelled, kill the
    scenario's sandbox (the runner then returns, and its result is discarded)."""
    settings = get_settings()
    stop = threading.Event()

    def beat() -> None:
        while not stop.wait(max(settings.lease_seconds / 3, 0.5)):
            try:
                with get_database().session() as session:
                    active = evaluation.heartbeat(session, settings, run_id, worker)
            except SQLAlchemyError as exc:
                log.warning("lease heartbeat of run %s failed: %s", run_id, exc)
                continue
            if not active:
                from evaluator import sandbox

                sandbox.cleanup(labels, settings)
                return

    thread = threading.Thread(target=beat, name=f"lease-run-{run_id}", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def reap_once() -> evaluation.Reaped:
    """Re-send work whose lease expired (see :func:`server.services.evaluation.reap`)."""
    queue = _queue()
    try:
        queue_empty = queue.depth() == 0
    except BROKER_ERRORS as exc:
        log.warning("reaper cannot read the queue: %s", exc)
        return evaluation.Reaped()
    with get_database().session() as session:
        reaped = evaluation.reap(session, get_settings(), queue_empty=queue_empty)
    for plan in reaped.plans:
        send_plan(queue, plan)
    for submission_id in reaped.submission_ids:
        queue.evaluate(submission_id)
    if reaped.plans or reaped.submission_ids:
        log.warning(
            "reaper re-sent %d run(s) and %d submission(s)",
            len(reaped.plans),
            len(reaped.submission_ids),
        )
    return reaped


_reaper_stop = threading.Event()


@worker_ready.connect
def _start_reaper(**_: Any) -> None:
    interval = get_settings().reaper_interval_s

    def loop() -> None:
        while not _reaper_stop.wait(interval):
            try:
                reap_once()
            except Exception:  # a bad round must not end the loop; logged with traceback
                log.exception("reaper round failed")

    threading.Thread(target=loop, name="arena-reaper", daemon=True).start()


@worker_shutdown.connect
def _stop_reaper(**_: Any) -> None:
    _reaper_stop.set()


@worker_process_init.connect
def _after_fork(**_: Any) -> None:
    get_database().after_fork()
    _queue.cache_clear()
