"""/team: the caller's team and the uploads it has left today."""

from __future__ import annotations

from fastapi import APIRouter

from server.api.contract import errors
from server.api.deps import CurrentTeam, SandboxDep, ServiceDep, SessionDep
from server.schemas import TeamStatus
from server.services import standing

router = APIRouter(prefix="/team", tags=["submissions"], responses=errors(401))


@router.get("", response_model=TeamStatus)
def team_status(
    session: SessionDep, service: ServiceDep, sandbox: SandboxDep, team: CurrentTeam
) -> TeamStatus:
    """Per phase (its dates, whether it is open, what it hides) and track: uploads left until
    00:00 UTC and the daily quota."""
    return standing.team_status(session, service, sandbox, team)
