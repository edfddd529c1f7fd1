"""The FastAPI application factory (``uvicorn --factory server.app:create_app``)."""

from __future__ import annotations

import logging
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.responses import JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from sqlalchemy.exc import SQLAlchemyError
from starlette.exceptions import HTTPException as StarletteHTTPException

from arena.config import Settings, get_settings
from evaluator.viewer.page import WEB_DIR as REPLAY_WEB_DIR
from server.api.contract import allowed_methods
from server.api.main import api_router
from server.api.routes import docs_pages, pages
from server.api.security_headers import SecurityHeaders
from server.core.db import Database
from server.core.queue import TaskQueue
from server.services.errors import ServiceError
from server.services.leaderboard import LeaderboardCache
from server.status import IllegalTransition

STATIC_DIR = Path(__file__).resolve().parent / "static"
log = logging.getLogger(__name__)


def _warm(leaderboard: LeaderboardCache) -> None:
    try:
        leaderboard.warm()
    except SQLAlchemyError:
        # A database not yet migrated or unreachable: requests will say so themselves.
        log.warning("leaderboards not warmed at start", exc_info=True)


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        # In the background: the API answers at once, and the first leaderboard request finds
        # the boards computed instead of waiting for their resampling.
        warming = threading.Thread(
            target=_warm, args=(app.state.leaderboard,), name="leaderboard-warm", daemon=True
        )
        warming.start()
        yield
        warming.join(timeout=5)
        app.state.queue.close()
        app.state.db.dispose()

    app = FastAPI(
        title="Driving Arena",
        version="1",
        description=(
            "Evaluation service and leaderboard for autonomous-driving agents. "
            "What an agent observes and sends: [agent interface](/guide/agent-interface); "
            "the zip, limits and failure reasons: [submissions](/guide/submissions)."
        ),
        lifespan=lifespan,
        # Served by docs_pages from local assets (the defaults load Swagger UI from a CDN).
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.db = Database(settings.storage.resolved_database_url)
    app.state.queue = TaskQueue(settings)
    app.state.leaderboard = LeaderboardCache(app.state.db)

    @app.exception_handler(ServiceError)
    async def _service_error(_: Request, exc: ServiceError) -> JSONResponse:
        return JSONResponse({"detail": exc.message}, status_code=exc.status_code)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> Response:
        if exc.status_code == 405:
            allow = ", ".join(allowed_methods(app, request.url.path))
            exc.headers = {**(exc.headers or {}), "Allow": allow}
        return await http_exception_handler(request, exc)

    @app.exception_handler(IllegalTransition)
    async def _illegal(_: Request, exc: IllegalTransition) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=409)

    app.add_middleware(SecurityHeaders)
    app.include_router(api_router)
    app.include_router(pages.router)
    app.include_router(docs_pages.router)
    docs_pages.mount_docs_assets(app)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    # The replay viewer's script and styles, the same files `arena replay --format html` inlines.
    app.mount("/replay-static", StaticFiles(directory=REPLAY_WEB_DIR), name="replay_static")
    return app
