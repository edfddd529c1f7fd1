"""HTML pages: leaderboard, submit form, submission progress. They read the same service
functions as the API; the submit and submission pages talk to the API from the browser with the
team token the user typed (kept in the browser's session storage, never in a cookie)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Request
from fastapi import Path as PathParam
from fastapi.responses import HTMLResponse

from arena.config import EvaluationSettings
from arena.figures import interval_text, metric_text, percent
from server.api.deps import (
    MAX_ROW_ID,
    EvaluationDep,
    GapQuery,
    LeaderboardDep,
    PhaseQuery,
    ScenarioId,
    SessionDep,
    SuitesDep,
)
from server.api.security_headers import page_templates
from server.models import Phase, utcnow
from server.services import phases, scenarios
from server.services.errors import NotFound
from server.services.leaderboard import METRICS, rank_range, with_gap
from server.services.phases import DEFAULT_PHASE
from server.tracks import Track

templates = page_templates(Path(__file__).resolve().parents[2] / "templates")
# One way to write a figure and a rank range on every page (and in the CLI, the CSV, the API).
templates.env.globals.update(
    metric_text=metric_text,
    interval_text=interval_text,
    percent=percent,
    rank_statement=lambda entry: rank_range(entry).statement,
)
router = APIRouter(include_in_schema=False)


@router.get("/", response_class=HTMLResponse)
def leaderboard_page(
    request: Request,
    cache: LeaderboardDep,
    session: SessionDep,
    track: Track = Track.freestyle,
    phase: PhaseQuery = DEFAULT_PHASE,
    gap_from: GapQuery = None,
) -> HTMLResponse:
    known = phases.list_phases(session)
    if phase not in {p.name for p in known}:
        phase = DEFAULT_PHASE
    board = cache.get(track, phase).board
    if gap_from in {p.name for p in known} - {phase}:
        board = with_gap(board, cache.get(track, gap_from).board)
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


def _costs(phase: Phase, episodes: int, evaluation: EvaluationSettings) -> list[str]:
    """What makes a score of the phase take longer than one training and one episode each."""
    costs = []
    if episodes > 1 or phase.adaptive_target is not None:
        costs.append(phases.adaptive_cost(phase, evaluation) or phases.episodes_cost(episodes))
    if phase.training_seeds > 1:
        costs.append(phases.seeds_cost(phase.training_seeds))
    return costs


def _detail(phase: Phase, moment, episodes: int, evaluation: EvaluationSettings) -> str:
    """A phase as the submit form says it in full."""
    state = phases.state(phase, moment)
    if state == "closed":
        return f"{phase.name} closed {phase.ends_at:%Y-%m-%d %H:%M} UTC."
    if state != "open":
        return f"{phase.name} opens {phase.starts_at:%Y-%m-%d %H:%M} UTC."
    what = (
        "public scenarios, full results"
        if phases.team_sees_everything(phase)
        else "hidden suite, metrics only"
    )
    closes = f"closes {phase.ends_at:%Y-%m-%d %H:%M} UTC" if phase.ends_at else "never closes"
    return (
        "; ".join([f"Phase {phase.name}: {what}, {closes}", *_costs(phase, episodes, evaluation)])
        + "."
    )


@router.get("/submit", response_class=HTMLResponse)
def submit_page(request: Request, session: SessionDep, evaluation: EvaluationDep) -> HTMLResponse:
    # Every phase, a closed or future one too (disabled, saying when): a phase that just
    # vanished from the form would leave a team guessing.
    moment = utcnow()
    known = phases.list_phases(session)
    episodes = {p.name: phases.episodes_per_scenario(p, evaluation) for p in known}
    default = DEFAULT_PHASE
    if not any(p.name == default and phases.is_open(p, moment) for p in known):
        default = next((p.name for p in known if phases.is_open(p, moment)), DEFAULT_PHASE)
    return templates.TemplateResponse(
        request,
        "submit.html",
        {
            "tracks": list(Track),
            "phases": known,
            "states": {p.name: phases.state(p, moment) for p in known},
            "any_open": any(phases.is_open(p, moment) for p in known),
            "open_names": [p.name for p in known if phases.is_open(p, moment)],
            "default_phase": default,
            # Said before the upload, under the select (a phone cuts a long option): when it
            # closes, and what multiplies the time to a score (episodes, training seeds).
            "details": {p.name: _detail(p, moment, episodes[p.name], evaluation) for p in known},
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
            "token": "team",
            "back_url": f"/submissions/{submission_id}",
            "back_label": f"submission {submission_id}",
        },
    )


@router.get("/admin/submissions/{submission_id}/replays/{scenario_id}", response_class=HTMLResponse)
def admin_replay_page(
    request: Request,
    submission_id: Annotated[int, PathParam(ge=1, le=MAX_ROW_ID)],
    scenario_id: ScenarioId,
) -> HTMLResponse:
    """Any episode of any submission, hidden phases included, for an organiser: the data comes
    from the admin API with the admin token typed into this tab (scenario ids are listed by
    `arena admin submissions show ID`)."""
    return templates.TemplateResponse(
        request,
        "replay.html",
        {
            "scenario_id": scenario_id,
            "what": f"Submission {submission_id}, seen as an organiser (hidden phases included).",
            "api_url": f"/api/v1/admin/submissions/{submission_id}/replays/{scenario_id}",
            "token": "admin",
            "back_url": "/",
            "back_label": "leaderboard",
        },
    )


@router.get("/scenarios", response_class=HTMLResponse)
def scenarios_page(request: Request, suites: SuitesDep) -> HTMLResponse:
    try:
        entries = scenarios.public_scenarios(suites)
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
            "token": None,
            "back_url": "/scenarios",
            "back_label": "public scenarios",
        },
    )
