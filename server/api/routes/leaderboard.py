"""/leaderboard: ranked best submission per team, as JSON and CSV."""

from __future__ import annotations

from fastapi import APIRouter, Response

from server.api.deps import LeaderboardDep
from server.models import Track
from server.services.leaderboard import to_csv

router = APIRouter(tags=["leaderboard"])


@router.get(
    "/leaderboard", response_class=Response, responses={200: {"description": "Leaderboard JSON"}}
)
def leaderboard(cache: LeaderboardDep, track: Track = Track.freestyle) -> Response:
    # Served from the cached, already-serialised board: no database work on most requests.
    return Response(cache.get(track).json, media_type="application/json")


@router.get("/leaderboard.csv", response_class=Response)
def leaderboard_csv(cache: LeaderboardDep, track: Track = Track.freestyle) -> Response:
    return Response(
        to_csv(cache.get(track).board),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="leaderboard-{track}.csv"'},
    )
