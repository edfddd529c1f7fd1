"""Dependencies of the API routes: the settings (whole, or the one group a route needs), the
session, the artifact store, the caller's team, the admin check and the ownership check. Each is
written once here and declared by the handlers that need it."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Query, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from arena.config import (
    EvaluationSettings,
    SandboxSettings,
    ServiceSettings,
    Settings,
    StorageSettings,
    SuiteSettings,
)
from server.core.artifacts import ArtifactStore, artifact_store
from server.core.db import Database
from server.core.queue import TaskQueue
from server.models import Submission, Team
from server.services.leaderboard import LeaderboardCache
from server.services.teams import team_for_token
from server.tokens import same_secret

bearer = HTTPBearer(auto_error=False)
# Row ids are 32-bit integers on PostgreSQL (64-bit on SQLite): a larger id in a path or query
# is refused (422) before it reaches a driver that cannot bind it (which answered 500).
MAX_ROW_ID = 2**31 - 1
RowId = Annotated[int, Path(ge=1, le=MAX_ROW_ID)]


def get_settings_dep(request: Request) -> Settings:
    return request.app.state.settings


SettingsDep = Annotated[Settings, Depends(get_settings_dep)]


def get_storage_settings(settings: SettingsDep) -> StorageSettings:
    return settings.storage


def get_suite_settings(settings: SettingsDep) -> SuiteSettings:
    return settings.suites


def get_sandbox_settings(settings: SettingsDep) -> SandboxSettings:
    return settings.sandbox


def get_evaluation_settings(settings: SettingsDep) -> EvaluationSettings:
    return settings.evaluation


def get_service_settings(settings: SettingsDep) -> ServiceSettings:
    return settings.service


StorageDep = Annotated[StorageSettings, Depends(get_storage_settings)]
SuitesDep = Annotated[SuiteSettings, Depends(get_suite_settings)]
SandboxDep = Annotated[SandboxSettings, Depends(get_sandbox_settings)]
EvaluationDep = Annotated[EvaluationSettings, Depends(get_evaluation_settings)]
ServiceDep = Annotated[ServiceSettings, Depends(get_service_settings)]


def get_db(request: Request) -> Database:
    return request.app.state.db


def get_queue(request: Request) -> TaskQueue:
    return request.app.state.queue


async def get_leaderboard_cache(request: Request) -> LeaderboardCache:
    return request.app.state.leaderboard


DatabaseDep = Annotated[Database, Depends(get_db)]


def get_session(db: DatabaseDep) -> Iterator[Session]:
    """A read session for the request; changes go through service functions, which open their
    own short write transactions."""
    with db.read_session() as session:
        yield session


def get_store(storage: StorageDep, db: DatabaseDep) -> ArtifactStore:
    return artifact_store(storage, db)


StoreDep = Annotated[ArtifactStore, Depends(get_store)]
QueueDep = Annotated[TaskQueue, Depends(get_queue)]
LeaderboardDep = Annotated[LeaderboardCache, Depends(get_leaderboard_cache)]
SessionDep = Annotated[Session, Depends(get_session)]
Credentials = Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]


def _unauthorized(message: str) -> HTTPException:
    return HTTPException(
        status.HTTP_401_UNAUTHORIZED, message, headers={"WWW-Authenticate": "Bearer"}
    )


def get_current_team(db: DatabaseDep, credentials: Credentials) -> Team:
    """The caller's team, looked up in a transaction of its own (an upload must not hold one
    open while its body streams in). The returned row is detached: id and name only."""
    if credentials is None:
        raise _unauthorized("send your team token: Authorization: Bearer <token>")
    with db.read_session() as session:
        team = team_for_token(session, credentials.credentials)
        if team is None:
            raise _unauthorized("unknown or revoked team token")
        session.expunge(team)
    return team


CurrentTeam = Annotated[Team, Depends(get_current_team)]


def require_admin(service: ServiceDep, credentials: Credentials) -> None:
    if service.admin_token is None:
        raise HTTPException(status.HTTP_403_FORBIDDEN, "no admin token is configured")
    if credentials is None or not same_secret(credentials.credentials, service.admin_token):
        raise _unauthorized("admin token required")


AdminDep = Depends(require_admin)


def is_admin(service: ServiceDep, credentials: Credentials) -> bool:
    """Whether the caller sent the admin token (for routes that show organisers more)."""
    return (
        service.admin_token is not None
        and credentials is not None
        and same_secret(credentials.credentials, service.admin_token)
    )


IsAdmin = Annotated[bool, Depends(is_admin)]


def get_owned_submission(
    session: SessionDep, team: CurrentTeam, submission_id: RowId
) -> Submission:
    """The submission, if it belongs to the caller's team. Another team's submission is reported
    as missing (404), so ids reveal nothing."""
    submission = session.get(Submission, submission_id)
    if submission is None or submission.team_id != team.id:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no submission {submission_id}")
    return submission


OwnedSubmission = Annotated[Submission, Depends(get_owned_submission)]


ScenarioId = Annotated[
    str,
    Path(max_length=128, pattern=r"^[A-Za-z0-9_.-]+$", description="A scenario id."),
]


PhaseQuery = Annotated[
    str,
    Query(max_length=32, pattern=r"^[A-Za-z0-9_-]+$", description="The competition phase."),
]
GapQuery = Annotated[
    str | None,
    Query(
        max_length=32,
        pattern=r"^[A-Za-z0-9_-]+$",
        description="Another phase (e.g. validation): each entry's generalisation gap to its "
        "team's entry there.",
    ),
]
