"""Sending work to the Celery workers, by task name (the API never imports the tasks)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from celery import Celery
from kombu.exceptions import OperationalError

from arena.config import Settings
from arena.episodes import Episode
from server.core.celery_app import (
    COMMAND_SIMULATOR_CORE,
    QUEUE,
    TASK_AGGREGATE,
    TASK_EVALUATE,
    TASK_SCENARIO,
    TASK_TRAIN,
    TASK_VALIDATE,
    create_celery_app,
    is_embedded_broker,
    reaches_workers,
)

# What sending to or reading from an unreachable broker raises (kombu wraps most as
# OperationalError; a refused socket can surface as OSError).
BROKER_ERRORS = (OperationalError, OSError)


@dataclass(frozen=True)
class RunPlan:
    """Episode tasks to send for a run (and whether its aggregation is due)."""

    run_id: int
    episodes: tuple[Episode, ...] = ()
    aggregate: bool = False


def scenario_task_id(run_id: int, episode: Episode) -> str:
    """Deterministic, so cancel can revoke a run's queued tasks without having stored their ids."""
    return f"run-{run_id}-{episode.name}"


class TaskQueue:
    """Call only after the database transaction that made the work visible has committed."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings

    @cached_property
    def celery(self) -> Celery:
        return create_celery_app(self.settings)

    def evaluate(self, submission_id: int) -> None:
        self.celery.send_task(TASK_EVALUATE, kwargs={"submission_id": submission_id}, queue=QUEUE)

    def run_scenario(self, run_id: int, episode: Episode) -> None:
        self.celery.send_task(
            TASK_SCENARIO,
            kwargs={"run_id": run_id, "scenario_id": episode.scenario_id, "episode": episode.index},
            task_id=scenario_task_id(run_id, episode),
            queue=QUEUE,
        )

    def validate(self, submission_id: int) -> None:
        self.celery.send_task(TASK_VALIDATE, kwargs={"submission_id": submission_id}, queue=QUEUE)

    def train(self, training_id: int) -> None:
        self.celery.send_task(TASK_TRAIN, kwargs={"training_id": training_id}, queue=QUEUE)

    def aggregate(self, run_id: int) -> None:
        self.celery.send_task(TASK_AGGREGATE, kwargs={"run_id": run_id}, queue=QUEUE)

    def send(self, plan: RunPlan) -> None:
        for episode in plan.episodes:
            self.run_scenario(plan.run_id, episode)
        if plan.aggregate:
            self.aggregate(plan.run_id)

    def revoke(self, task_ids: list[str]) -> None:
        """Best effort: tasks also check the run's status before doing anything."""
        if task_ids and not is_embedded_broker(self.settings.storage.resolved_broker_url):
            self.celery.control.revoke(task_ids)

    def depth(self) -> int:
        """Messages waiting in the evaluation queue."""
        with self.celery.connection_for_read() as connection:
            connection.ensure_connection(max_retries=1)  # fail fast: health checks call this
            declared = connection.default_channel.queue_declare(
                QUEUE, durable=True, auto_delete=False
            )
            return declared.message_count

    def workers(self) -> list[str] | None:
        """Names of the workers that answer a ping; None where the broker cannot reach them."""
        if not reaches_workers(self.settings.storage.resolved_broker_url):
            return None
        replies = self.celery.control.ping(timeout=1.0) or []
        return sorted(name for reply in replies for name in reply)

    def worker_cores(self, expected: int) -> dict[str, str] | None:
        """The per-step core each answering worker's simulator runs (``sim.compiled.core_status``
        in its process), by worker name; None where the broker cannot broadcast. Waits only
        until ``expected`` workers answered."""
        if is_embedded_broker(self.settings.storage.resolved_broker_url):
            return None
        replies = self.celery.control.broadcast(
            COMMAND_SIMULATOR_CORE, reply=True, timeout=1.0, limit=expected
        )
        return {
            name: str(answer.get("core", "unknown (the worker does not say)"))
            for reply in replies or []
            for name, answer in reply.items()
        }

    def close(self) -> None:
        if "celery" in self.__dict__:
            self.celery.close()
