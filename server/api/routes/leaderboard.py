"""/leaderboard: ranked best submission per team, per phase and track, as JSON and CSV."""

from __future__ import annotations

from fastapi import APIRouter, Response
from starlette.concurrency import run_in_threadpool

from server.api.contract import errors
from server.api.deps import GapQuery, LeaderboardDep, PhaseQuery
from server.schemas import Leaderboard
from server.services.leaderboard import LeaderboardCache, to_csv, with_gap
from server.services.phases import DEFAULT_PHASE
from server.tracks import Track

router = APIRouter(tags=["leaderboard"], responses=errors(404, 422))


@router.get(
    "/leaderboard", response_class=Response, responses={200: {"description": "Leaderboard JSON"}}
)
async def leaderboard(
    cache: LeaderboardDep,
    track: Track = Track.freestyle,
    phase: PhaseQuery = DEFAULT_PHASE,
    gap_from: GapQuery = None,
) -> Response:
    if gap_from is not None:
        board = await run_in_threadpool(_with_gap, cache, track, phase, gap_from)
        return Response(board.model_dump_json(), media_type="application/json")
    # The cached, already-serialised board, straight from the event loop; only when the cache
    # must look at the database does the request go to the thread pool.
    cached = cache.fresh(track, phase) or await run_in_threadpool(cache.get, track, phase)
    return Response(cached.json, media_type="application/json")


def _with_gap(cache: LeaderboardCache, track: Track, phase: str, gap_from: str) -> Leaderboard:
    return with_gap(cache.get(track, phase).board, cache.get(track, gap_from).board)


@router.get("/leaderboard.csv", response_class=Response)
def leaderboard_csv(
    cache: LeaderboardDep,
    track: Track = Track.freestyle,
    phase: PhaseQuery = DEFAULT_PHASE,
    gap_from: GapQuery = None,
) -> Response:
    board = (
        cache.get(track, phase).board
        if gap_from is None
        else _with_gap(cache, track, phase, gap_from)
    )
    return Response(
        to_csv(board),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="leaderboard-{phase}-{track}.csv"'},
    )
