"""Teams and their API tokens."""

from __future__ import annotations

import re
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from arena.names import did_you_mean
from server.models import ApiToken, Submission, Team, utcnow
from server.services.errors import Conflict, InvalidInput, NotFound
from server.tokens import hash_token, new_token

TEAM_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9 _.-]{0,63}$")


@dataclass(frozen=True)
class TeamRow:
    id: int
    name: str
    submissions: int
    created_at: object


def create_team(session: Session, name: str) -> tuple[Team, str]:
    """A new team and its first token (returned in clear once; only its hash is stored)."""
    # fullmatch: with match, `$` also matches before a final newline ("alpha\n" passed).
    if not TEAM_NAME.fullmatch(name):
        raise InvalidInput(f"team name {name!r}: use 1-64 letters, digits, spaces, '_', '.' or '-'")
    if session.scalar(select(Team.id).where(Team.name == name)) is not None:
        raise Conflict(f"team {name!r} already exists")
    team = Team(name=name)
    session.add(team)
    session.flush()
    return team, _issue_token(session, team)


def rotate_token(session: Session, team: Team) -> str:
    """Revoke every live token of ``team`` and issue a new one."""
    for token in team.tokens:
        if token.revoked_at is None:
            token.revoked_at = utcnow()
    return _issue_token(session, team)


def _issue_token(session: Session, team: Team) -> str:
    token = new_token()
    session.add(ApiToken(team_id=team.id, token_sha256=hash_token(token)))
    session.flush()
    return token


def team_for_token(session: Session, token: str) -> Team | None:
    return session.scalar(
        select(Team)
        .join(ApiToken)
        .where(ApiToken.token_sha256 == hash_token(token), ApiToken.revoked_at.is_(None))
    )


def get_team(session: Session, name: str) -> Team:
    team = session.scalar(select(Team).where(Team.name == name))
    if team is None:
        known = session.scalars(select(Team.name))
        raise NotFound(f"no team named {name!r}{did_you_mean(name, known)}")
    return team


def list_teams(session: Session) -> list[TeamRow]:
    counts = (
        select(Submission.team_id, func.count().label("n")).group_by(Submission.team_id).subquery()
    )
    rows = session.execute(
        select(Team.id, Team.name, func.coalesce(counts.c.n, 0), Team.created_at)
        .outerjoin(counts, counts.c.team_id == Team.id)
        .order_by(Team.id)
    )
    return [TeamRow(*row) for row in rows]
