"""/healthz: is the API up, can it reach the database and the broker."""

from __future__ import annotations

from fastapi import APIRouter, Response, status
from sqlalchemy import text

from server.api.deps import DatabaseDep, QueueDep
from server.schemas import Health

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
def healthz(db: DatabaseDep, queue: QueueDep, response: Response) -> Health:
    try:
        with db.read_session() as session:
            session.execute(text("SELECT 1"))
        database = True
    except Exception:
        database = False
    try:
        queue.depth()
        broker = True
    except Exception:
        broker = False
    healthy = database and broker
    if not healthy:
        response.status_code = status.HTTP_503_SERVICE_UNAVAILABLE
    return Health(status="ok" if healthy else "degraded", database=database, broker=broker)
