"""/leaderboard: ranked best submission per team, per phase and track, as JSON and CSV."""

from __future__ import annotations

from fastapi import APIRouter, Response
from starlette.concurrency import run_in_threadpool

from server.api.contract import errors
from server.api.deps import LeaderboardDep, PhaseQuery
from server.services.leaderboard import to_csv
from server.services.phases import DEFAULT_PHASE
from server.tracks import Track

router = APIRouter(tags=["leaderboard"], responses=errors(404, 422))


@router.get(
    "/leaderboard", response_class=Response, responses={200: {"description": "Leaderboard JSON"}}
)
async def leaderboard(
    cache: LeaderboardDep, track: Track = Track.freestyle, phase: PhaseQuery = DEFAULT_PHASE
) -> Response:
    # The cached, already-serialised board, straight from the event loop; only when the cache
    # must look at the database does the request go to the thread pool.
    cached = cache.fresh(track, phase) or await run_in_threadpool(cache.get, track, phase)
    return Response(cached.json, media_type="application/json")


@router.get("/leaderboard.csv", response_class=Response)
def leaderboard_csv(
    cache: LeaderboardDep, track: Track = Track.freestyle, phase: PhaseQuery = DEFAULT_PHASE
) -> Response:
    return Response(
        to_csv(cache.get(track, phase).board),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="leaderboard-{phase}-{track}.csv"'},
    )
