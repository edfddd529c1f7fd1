"""The versioned API router: every resource router, collected in one place."""

from __future__ import annotations

from fastapi import APIRouter

from server.api.routes import admin, health, leaderboard, metrics, scenarios, submissions, team

api_router = APIRouter(prefix="/api/v1")
for module in (submissions, team, leaderboard, scenarios, health, metrics, admin):
    api_router.include_router(module.router)
