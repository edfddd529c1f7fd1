"""HTML pages: leaderboard, submit form, submission progress. They read the same service
functions as the API; the submit and submission pages talk to the API from the browser with the
team token the user typed (kept in the browser's session storage, never in a cookie)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Request
from fastapi import Path as PathParam
from fastapi.responses import HTMLResponse

from server.api.deps import (
    MAX_ROW_ID,
    LeaderboardDep,
    PhaseQuery,
    ScenarioId,
    SessionDep,
    SettingsDep,
)
from server.api.security import page_templates
from server.services import phases, scenarios
from server.services.errors import NotFound
from server.services.leaderboard import METRICS
from server.services.phases import DEFAULT_PHASE
from server.tracks import Track

templates = page_templates(Path(__file__).resolve().parents[2] / "templates")
router = APIRouter(include_in_schema=False)


@router.get("/", response_class=HTMLResponse)
def leaderboard_page(
    request: Request,
    cache: LeaderboardDep,
    session: SessionDep,
    track: Track = Track.freestyle,
    phase: PhaseQuery = DEFAULT_PHASE,
) -> HTMLResponse:
    known = phases.list_phases(session)
    if phase not in {p.name for p in known}:
        phase = DEFAULT_PHASE
    board = cache.get(track, phase).board
    families = sorted({family for entry in board.entries for family in entry.families})
    return templates.TemplateResponse(
        request,
        "leaderboard.html",
        {
            "board": board,
            "phases": known,
            "tracks": list(Track),
            "metrics": METRICS,
            "families": families,
        },
    )


@router.get("/submit", response_class=HTMLResponse)
def submit_page(request: Request, session: SessionDep, settings: SettingsDep) -> HTMLResponse:
    open_phases = phases.open_phases(session)
    episodes = {p.name: phases.episodes_per_scenario(p, settings) for p in open_phases}
    return templates.TemplateResponse(
        request,
        "submit.html",
        {
            "tracks": list(Track),
            "phases": open_phases,
            "default_phase": DEFAULT_PHASE,
            # Said before the upload: several episodes multiply the time to a score.
            "costs": {name: phases.episodes_cost(n) for name, n in episodes.items() if n > 1},
        },
    )


@router.get("/submissions/{submission_id}", response_class=HTMLResponse)
def submission_page(
    request: Request, submission_id: Annotated[int, PathParam(ge=1, le=MAX_ROW_ID)]
) -> HTMLResponse:
    return templates.TemplateResponse(
        request, "submission.html", {"submission_id": submission_id, "metrics": METRICS}
    )


@router.get("/my-submissions", response_class=HTMLResponse)
def my_submissions_page(request: Request) -> HTMLResponse:
    """The team's submissions; the list comes from the API with the token held in the tab."""
    return templates.TemplateResponse(request, "my_submissions.html", {"metrics": METRICS})


@router.get("/submissions/{submission_id}/replays/{scenario_id}", response_class=HTMLResponse)
def submission_replay_page(
    request: Request,
    submission_id: Annotated[int, PathParam(ge=1, le=MAX_ROW_ID)],
    scenario_id: ScenarioId,
) -> HTMLResponse:
    """One episode of the team's submission; the data comes from the API with the tab's token."""
    return templates.TemplateResponse(
        request,
        "replay.html",
        {
            "scenario_id": scenario_id,
            "what": f"Submission {submission_id}: your agent's episode.",
            "api_url": f"/api/v1/submissions/{submission_id}/replays/{scenario_id}",
            "needs_token": True,
            "back_url": f"/submissions/{submission_id}",
            "back_label": f"submission {submission_id}",
        },
    )


@router.get("/scenarios", response_class=HTMLResponse)
def scenarios_page(request: Request, settings: SettingsDep) -> HTMLResponse:
    try:
        entries = scenarios.public_scenarios(settings)
    except NotFound:
        entries = ()
    return templates.TemplateResponse(request, "scenarios.html", {"scenarios": entries})


@router.get("/scenarios/{scenario_id}/replay", response_class=HTMLResponse)
def public_replay_page(request: Request, scenario_id: ScenarioId) -> HTMLResponse:
    return templates.TemplateResponse(
        request,
        "replay.html",
        {
            "scenario_id": scenario_id,
            "what": "The expert's drive through this public scenario (the reference planner, or "
            "the recorded driver of a replay).",
            "api_url": f"/api/v1/scenarios/public/{scenario_id}/replay",
            "needs_token": False,
            "back_url": "/scenarios",
            "back_label": "public scenarios",
        },
    )
