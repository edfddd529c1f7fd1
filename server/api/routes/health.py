"""/healthz: is the API up, can it reach the database and the broker."""

from __future__ import annotations

from fastapi import APIRouter, Response, status

from server.api.contract import errors
from server.api.deps import DatabaseDep, QueueDep
from server.schemas import Health
from server.services.monitoring import reachability

router = APIRouter(tags=["health"], responses=errors(503))


@router.get("/healthz", response_model=Health)
def healthz(db: DatabaseDep, queue: QueueDep, response: Response) -> Health:
    reached = reachability(db, queue)
    if not reached.healthy:
        response.status_code = status.HTTP_503_SERVICE_UNAVAILABLE
    return Health(
        status="ok" if reached.healthy else "degraded",
        database=reached.database,
        broker=reached.broker,
    )
