"""Celery tasks of the service: thin wrappers around :mod:`server.services` and the job engine
(:mod:`server.jobs.engine`).

Every task is declared with :func:`arena_task` (late acknowledgement, requeue when the worker
process dies, one queue, time limits), takes keyword-only ids, returns early when the database
says its work is done, and sends follow-up tasks only after its transaction committed. Any task
can therefore be delivered twice: the unique (run, scenario, episode) row makes the second a
no-op.

``evaluate_submission`` fans out one ``run_scenario`` per episode of each scenario (several of
each reactive scenario when the phase asks for them); the ``run_scenario`` that finishes the last
one sends ``aggregate_run``, which scores the run from its stored records. An offline (Track 2)
submission first goes through ``train_submission``, which runs its ``train.py`` in the sandbox,
stores the trained output and then fans out the evaluation of that output. Episodes and trainings
are job kinds of the engine (:mod:`server.worker.episodes`, :mod:`server.worker.trainings`): one
claim, heartbeat, fence, hand-back and reaper for both.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from celery import shared_task
from celery.signals import (
    worker_process_init,
    worker_ready,
    worker_shutdown,
    worker_shutting_down,
)
from celery.worker.control import inspect_command

from arena.config import get_settings
from arena.suite import hidden_suite_dir
from evaluator.sandbox.backend import SANDBOX_LABEL, owner_labels
from evaluator.sandbox.docker_backend import remove_binding
from evaluator.sandbox.warm_pool import warm_agents
from server.core.celery_app import (
    COMMAND_SIMULATOR_CORE,
    QUEUE,
    TASK_AGGREGATE,
    TASK_EVALUATE,
    TASK_SCENARIO,
    TASK_TRAIN,
    TASK_VALIDATE,
)
from server.core.permissions import close_service_folders
from server.jobs import engine, heartbeat
from server.jobs.engine import INFRASTRUCTURE_RETRIES
from server.jobs.kind import JobKind
from server.services import adaptive, evaluation, submissions, training
from server.worker import local
from server.worker.episodes import EPISODES
from server.worker.trainings import TRAININGS
from server.worker.validations import VALIDATIONS
from sim.compiled import core_status
from submissions.intake.archive import remove_tree

log = logging.getLogger(__name__)

# [s] One scenario: agent start-up plus the episode limit (600 s) plus a SUMO retry.
SCENARIO_TIME_LIMIT_S = 1800
BOOKKEEPING_TIME_LIMIT_S = 300
# A backstop: each sandboxed step of a validation has ARENA_INTAKE_TIMEOUT_S, plus pip's download.
VALIDATE_TIME_LIMIT_S = 3600
# A backstop only (the thread pool enforces no task time limit): the training's own budget,
# ARENA_TRAIN_TIMEOUT_S, is enforced by evaluator.training.
TRAIN_TIME_LIMIT_S = 24 * 3600
# Every job kind of the engine: what the reaper looks through.
JOB_KINDS: tuple[JobKind, ...] = (VALIDATIONS, EPISODES, TRAININGS)


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


@arena_task(
    TASK_VALIDATE, time_limit=VALIDATE_TIME_LIMIT_S, bind=True, max_retries=INFRASTRUCTURE_RETRIES
)
def validate_submission(self, *, submission_id: int) -> None:
    """An upload validated in the sandbox: queued (and sent to evaluation) or rejected."""
    engine.run_job(VALIDATIONS, self, get_settings(), local.worker(), submission_id=submission_id)


@arena_task(TASK_EVALUATE, time_limit=BOOKKEEPING_TIME_LIMIT_S)
def evaluate_submission(*, submission_id: int) -> None:
    settings = get_settings()
    with local.database().session() as session:
        # Offline submissions train first; the training's end starts their evaluation.
        training_ids = training.start_training(session, settings.service, submission_id)
        plan = (
            None if training_ids else evaluation.start_evaluation(session, settings, submission_id)
        )
    for training_id in training_ids:  # one per seed
        local.queue().train(training_id)
    if plan is not None:
        local.queue().send(plan)


@arena_task(
    TASK_TRAIN, time_limit=TRAIN_TIME_LIMIT_S, bind=True, max_retries=INFRASTRUCTURE_RETRIES
)
def train_submission(self, *, training_id: int) -> None:
    engine.run_job(TRAININGS, self, get_settings(), local.worker(), training_id=training_id)


@arena_task(
    TASK_SCENARIO,
    time_limit=SCENARIO_TIME_LIMIT_S,
    bind=True,
    max_retries=INFRASTRUCTURE_RETRIES,
)
def run_scenario(self, *, run_id: int, scenario_id: str, episode: int = 0) -> None:
    engine.run_job(
        EPISODES,
        self,
        get_settings(),
        local.worker(),
        run_id=run_id,
        scenario_id=scenario_id,
        episode=episode,
    )


@arena_task(TASK_AGGREGATE, time_limit=BOOKKEEPING_TIME_LIMIT_S)
def aggregate_run(*, run_id: int) -> None:
    with local.database().session() as session:
        # An adaptive run whose interval is still too wide gets another round instead.
        plan = adaptive.next_round(session, local.store(), run_id)
        if plan is None:
            evaluation.finish_run(session, local.store(), run_id)
    if plan is not None:
        local.queue().send(plan)


def reap_once() -> dict[str, int]:
    """Re-send work whose lease expired, of every job kind (see :func:`engine.reap_once`)."""
    return engine.reap_once(JOB_KINDS, get_settings().service, local.queue())


def remove_finished_scratch() -> int:
    """Delete this process's unpacked submissions and models whose runs have ended."""
    with local.database().read_session() as session:
        uploads, models = submissions.keys_in_work(session)
    return local.forget_finished(uploads, models)


@inspect_command(name=COMMAND_SIMULATOR_CORE)
def simulator_core(state: Any, **_: Any) -> dict[str, str]:
    """The per-step core this worker's simulator runs (`arena admin status` asks): a worker
    installed without a compiler, or with ARENA_PURE_PYTHON set, runs the pure-Python
    reference, several times slower."""
    return {"core": core_status()}


_reaper_stop = threading.Event()


@worker_shutting_down.connect
def _hand_back_running_jobs(**_: Any) -> None:
    heartbeat.shutting_down.set()


@worker_ready.connect
def _close_service_folders(**_: Any) -> None:
    """The data folder and the hidden suite, closed to the agents' uid (server.core.permissions)."""
    settings = get_settings()
    data_dir = settings.storage.resolved_data_dir
    close_service_folders(data_dir, hidden_suite_dir(settings.suites, data_dir))


@worker_ready.connect
def _start_reaper(**_: Any) -> None:
    interval = get_settings().service.reaper_interval_s

    def loop() -> None:
        while not _reaper_stop.wait(interval):
            try:
                reap_once()
                warm_agents().close_idle(get_settings().sandbox.warm_agent_idle_s)
                remove_finished_scratch()
            except Exception:  # a bad round must not end the loop; logged with traceback
                log.exception("reaper round failed")

    threading.Thread(target=loop, name="arena-reaper", daemon=True).start()


@worker_shutdown.connect
def _stop_reaper(**_: Any) -> None:
    _reaper_stop.set()


@worker_shutdown.connect
def _remove_scratch(**_: Any) -> None:
    """This process's scratch (prepared submissions, records, models) ends with it."""
    remove_tree(local.scratch())


@worker_ready.connect
def _remove_orphan_scratch(**_: Any) -> None:
    """Scratch of this host's worker processes that died without removing theirs, and the
    Docker containers that bind it (a SIGKILLed worker's intake or warm agent: a container
    outlives its process, bubblewrap's sandboxes do not)."""
    orphans = local.orphan_scratch()
    if orphans:
        data_dir = get_settings().storage.resolved_data_dir
        removed = remove_binding(orphans, {SANDBOX_LABEL: "1", **owner_labels(data_dir)})
        if removed:
            log.warning("removed %d sandbox(es) of worker processes that died", removed)
    for folder in orphans:
        remove_tree(folder)


@worker_shutdown.connect
def _close_warm_agents(**_: Any) -> None:
    """The warm agent sandboxes this worker kept (one per submission it ran and thread, see
    docs/protocol.md) end with it; running jobs were handed back before."""
    warm_agents().close()


@worker_process_init.connect
def _after_fork(**_: Any) -> None:
    local.database().after_fork()
    local.clear()
    heartbeat.heartbeat.cache_clear()
