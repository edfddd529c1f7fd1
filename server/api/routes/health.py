"""/healthz: is the API up, can it reach the database and the broker."""

from __future__ import annotations

from fastapi import APIRouter, Response, status
from sqlalchemy import text
from sqlalchemy.exc import SQLAlchemyError

from server.api.contract import errors
from server.api.deps import DatabaseDep, QueueDep
from server.schemas import Health
from server.services.queue import BROKER_ERRORS

router = APIRouter(tags=["health"], responses=errors(503))


@router.get("/healthz", response_model=Health)
def healthz(db: DatabaseDep, queue: QueueDep, response: Response) -> Health:
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
    healthy = database and broker
    if not healthy:
        response.status_code = status.HTTP_503_SERVICE_UNAVAILABLE
    return Health(status="ok" if healthy else "degraded", database=database, broker=broker)
