"""The Celery app, made by a factory from the settings.

Importing this module creates nothing but an unconfigured ``app`` object (what ``celery -A
server.core.celery_app`` needs); it reads the settings only when Celery first configures it. Every
other caller builds its own with :func:`create_celery_app`. Task names and the queue are constants
so the API can enqueue by name without importing the tasks (and their heavy imports).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from celery import Celery

from arena.config import Settings, get_settings

QUEUE = "arena"
TASK_EVALUATE = "arena.evaluate_submission"
TASK_SCENARIO = "arena.run_scenario"
TASK_AGGREGATE = "arena.aggregate_run"
TASK_TRAIN = "arena.train_submission"
TASK_VALIDATE = "arena.validate_submission"
# The remote-control command a worker answers with its simulator core (`arena admin status`).
COMMAND_SIMULATOR_CORE = "arena_simulator_core"


def is_embedded_broker(broker_url: str) -> bool:
    """Kombu's SQLAlchemy transport (the no-Redis default): no broadcast, so no remote control."""
    return broker_url.startswith("sqla+")


def reaches_workers(broker_url: str) -> bool:
    """Whether a ping can reach a worker process through this broker: not through the embedded
    one, nor kombu's in-memory transport (the fast tier's), which passes messages between the
    threads of one process only, so a ping would only wait out its timeout."""
    return not (is_embedded_broker(broker_url) or broker_url.startswith("memory://"))


def celery_config(settings: Settings) -> dict[str, Any]:
    broker = settings.storage.resolved_broker_url
    config: dict[str, Any] = {
        "broker_url": broker,
        "imports": ["server.worker.tasks"],
        "task_default_queue": QUEUE,
        "task_ignore_result": True,
        "task_serializer": "json",
        "accept_content": ["json"],
        # One message at a time per process: a scenario takes minutes, prefetching would starve
        # other workers and strand messages in a process that might die.
        "worker_prefetch_multiplier": 1,
        # Threads, not prefork: a scenario's real work happens in the simulator process the
        # runner starts for each episode (one libsumo per process), and multiprocessing cannot
        # start those from prefork's daemonic children. The runner enforces the episode time
        # limits itself; the task time limits below need prefork and are a backstop only there.
        "worker_pool": "threads",
        "worker_concurrency": settings.evaluation.jobs,
        "worker_hijack_root_logger": False,
        "broker_connection_retry_on_startup": True,
        "broker_connection_max_retries": None,
    }
    if is_embedded_broker(broker):
        database = broker.removeprefix("sqla+sqlite:///")
        Path(database).parent.mkdir(parents=True, exist_ok=True)
        config |= {"worker_enable_remote_control": False, "worker_send_task_events": False}
    else:
        # Unacknowledged messages come back after this long; the lease reaper re-queues lost work
        # much sooner, and results are idempotent, so a late redelivery only costs a no-op.
        options: dict[str, Any] = {"visibility_timeout": 6 * 3600}
        if settings.service.broker_key_prefix:
            options["global_keyprefix"] = settings.service.broker_key_prefix
        config["broker_transport_options"] = options
    return config


def create_celery_app(settings: Settings) -> Celery:
    app = Celery("arena", set_as_current=False)
    app.conf.update(celery_config(settings))
    return app


app = Celery("arena", set_as_current=False)


@app.on_configure.connect
def _configure_from_settings(sender: Celery, **_: Any) -> None:
    # The worker's bootstrap (`celery -A`): nothing above it to hand the settings down.
    sender.conf.update(celery_config(get_settings()))
