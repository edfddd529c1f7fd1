"""What the probes report: reachability of the database and broker, and service figures."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import func, select, text
from sqlalchemy.exc import SQLAlchemyError

from server.core.db import Database
from server.core.queue import BROKER_ERRORS, TaskQueue
from server.models import EvaluationRun, ScenarioResult, Submission
from server.status import RunStatus


@dataclass(frozen=True)
class Reachability:
    database: bool
    broker: bool

    @property
    def healthy(self) -> bool:
        return self.database and self.broker


@dataclass(frozen=True)
class ServiceFigures:
    queue_depth: float  # NaN when the broker cannot be read
    running_evaluations: int
    submissions: list[tuple[str, int]]  # status, count
    episodes: list[tuple[str, str, int]]  # status, reason, count


def reachability(db: Database, queue: TaskQueue) -> Reachability:
    try:
        with db.read_session() as session:
            session.execute(text("SELECT 1"))
        database = True
    except SQLAlchemyError:
        database = False
    try:
        queue.depth()
        broker = True
    except BROKER_ERRORS:
        broker = False
    return Reachability(database=database, broker=broker)


def service_figures(db: Database, queue: TaskQueue) -> ServiceFigures:
    """Read at scrape time from the database and broker, so every API replica answers the same."""
    try:
        depth = float(queue.depth())
    except BROKER_ERRORS:  # an unreachable broker must not break the scrape
        depth = float("nan")
    with db.read_session() as session:
        running = session.scalar(
            select(func.count())
            .select_from(EvaluationRun)
            .where(EvaluationRun.status == RunStatus.running)
        )
        submissions = session.execute(
            select(Submission.status, func.count()).group_by(Submission.status)
        ).all()
        episodes = session.execute(
            select(ScenarioResult.status, ScenarioResult.reason, func.count()).group_by(
                ScenarioResult.status, ScenarioResult.reason
            )
        ).all()
    return ServiceFigures(
        queue_depth=depth,
        running_evaluations=running or 0,
        submissions=[(str(status), count) for status, count in submissions],
        episodes=[(str(status), reason or "", count) for status, reason, count in episodes],
    )
