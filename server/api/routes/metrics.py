"""/metrics: Prometheus exposition of queue depth, running evaluations and submissions by status,
for anyone; episode outcomes by reason only with the admin token (read live by anyone, they told a
team, episode by episode, how its agent ended the hidden scenarios)."""

from __future__ import annotations

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
from prometheus_client.core import GaugeMetricFamily

from server.api.deps import DatabaseDep, IsAdmin, QueueDep
from server.core.db import Database
from server.core.queue import TaskQueue
from server.services.monitoring import service_figures

router = APIRouter(tags=["metrics"])


class ArenaCollector:
    def __init__(self, db: Database, queue: TaskQueue, *, episodes: bool) -> None:
        self.db = db
        self.queue = queue
        self.episodes = episodes

    def collect(self):
        figures = service_figures(self.db, self.queue)
        depth = GaugeMetricFamily("arena_queue_depth", "Tasks waiting in the evaluation queue")
        depth.add_metric([], figures.queue_depth)
        yield depth
        yield GaugeMetricFamily(
            "arena_running_evaluations",
            "Evaluation runs in progress",
            value=figures.running_evaluations,
        )
        by_status = GaugeMetricFamily(
            "arena_submissions", "Submissions by status", labels=["status"]
        )
        for status, count in figures.submissions:
            by_status.add_metric([status], count)
        yield by_status
        if not self.episodes:
            return
        episodes = GaugeMetricFamily(
            "arena_episodes", "Scenario episodes by outcome and reason", labels=["status", "reason"]
        )
        for status, reason, count in figures.episodes:
            episodes.add_metric([status, reason], count)
        yield episodes


# The token is optional here (anyone reads the service figures; organisers read more): an empty
# requirement beside the bearer one says so in the OpenAPI document.
OPTIONAL_BEARER = {"security": [{}, {"HTTPBearer": []}]}


@router.get("/metrics", response_class=Response, openapi_extra=OPTIONAL_BEARER)
def metrics(db: DatabaseDep, queue: QueueDep, admin: IsAdmin) -> Response:
    """Service figures (Prometheus); per-reason episode outcomes with the admin token only."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(ArenaCollector(db, queue, episodes=admin))
    return Response(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)
