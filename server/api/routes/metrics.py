"""/metrics: Prometheus exposition of queue depth, running evaluations and episode outcomes."""

from __future__ import annotations

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
from prometheus_client.core import GaugeMetricFamily
from sqlalchemy import func, select

from server.api.deps import DatabaseDep, QueueDep
from server.core.db import Database
from server.models import EvaluationRun, ScenarioResult, Submission
from server.services.queue import BROKER_ERRORS, TaskQueue
from server.status import RunStatus

router = APIRouter(tags=["metrics"])


class ArenaCollector:
    """Reads the figures from the database and broker at scrape time (any API replica answers the
    same), rather than counting events in one process's memory."""

    def __init__(self, db: Database, queue: TaskQueue) -> None:
        self.db = db
        self.queue = queue

    def collect(self):
        depth = GaugeMetricFamily("arena_queue_depth", "Tasks waiting in the evaluation queue")
        try:
            depth.add_metric([], self.queue.depth())
        except BROKER_ERRORS:  # an unreachable broker must not break the scrape
            depth.add_metric([], float("nan"))
        yield depth
        with self.db.read_session() as session:
            running = session.scalar(
                select(func.count())
                .select_from(EvaluationRun)
                .where(EvaluationRun.status == RunStatus.running)
            )
            submissions = session.execute(
                select(Submission.status, func.count()).group_by(Submission.status)
            ).all()
            outcomes = session.execute(
                select(ScenarioResult.status, ScenarioResult.reason, func.count()).group_by(
                    ScenarioResult.status, ScenarioResult.reason
                )
            ).all()
        yield GaugeMetricFamily(
            "arena_running_evaluations", "Evaluation runs in progress", value=running
        )
        by_status = GaugeMetricFamily(
            "arena_submissions", "Submissions by status", labels=["status"]
        )
        for status, count in submissions:
            by_status.add_metric([str(status)], count)
        yield by_status
        episodes = GaugeMetricFamily(
            "arena_episodes", "Scenario episodes by outcome and reason", labels=["status", "reason"]
        )
        for status, reason, count in outcomes:
            episodes.add_metric([status, reason or ""], count)
        yield episodes


@router.get("/metrics", response_class=Response)
def metrics(db: DatabaseDep, queue: QueueDep) -> Response:
    registry = CollectorRegistry(auto_describe=False)
    registry.register(ArenaCollector(db, queue))
    return Response(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)
