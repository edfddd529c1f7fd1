"""Deleting a team or a phase with everything that hangs off it (organisers only, after a
confirmation that says what goes): submissions, their evaluations, per-episode results, scores,
trainings, API tokens, and the uploads, records and trained models in the artifact store.

Refused while any of those submissions is still queued, training or running: a worker would
write into rows that are gone. Cancel them first.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from server.core.artifacts import ArtifactStore
from server.core.db import Database
from server.models import (
    ApiToken,
    EvaluationRun,
    Phase,
    ScenarioResult,
    Score,
    SeedSetScore,
    Submission,
    Team,
    TrainingJob,
)
from server.services import phases, teams
from server.services.errors import Conflict, InvalidInput
from server.services.evaluation import bump_leaderboard
from server.status import ACTIVE_SUBMISSION


@dataclass(frozen=True)
class Removal:
    """What deleting a team or phase removes (shown before the confirmation, and after)."""

    what: str  # "team alpha", "phase warmup"
    submissions: int
    evaluations: int
    episode_results: int
    trainings: int
    tokens: int

    def describe(self) -> str:
        return (
            f"{self.what}: {self.submissions} submission(s) with their uploads, "
            f"{self.evaluations} evaluation(s) ({self.episode_results} episode result(s) and "
            f"records), {self.trainings} training(s) with their trained models"
            + (f", {self.tokens} API token(s)" if self.tokens else "")
        )


def _submissions(session: Session, where) -> list[Submission]:
    return list(session.scalars(select(Submission).where(where).order_by(Submission.id)))


def _preview(what: str, submissions: list[Submission], tokens: int) -> Removal:
    runs = [run for s in submissions for run in s.runs]
    return Removal(
        what=what,
        submissions=len(submissions),
        evaluations=len(runs),
        episode_results=sum(len(run.results) for run in runs),
        trainings=sum(len(s.trainings) for s in submissions),
        tokens=tokens,
    )


def team_removal(session: Session, name: str) -> Removal:
    team = teams.get_team(session, name)
    return _preview(
        f"team {team.name}", _submissions(session, Submission.team_id == team.id), len(team.tokens)
    )


def phase_removal(session: Session, name: str) -> Removal:
    phase = phases.get_phase(session, name)
    if phase.name == phases.DEFAULT_PHASE:
        raise InvalidInput(
            f"phase {phase.name!r} is where uploads go when no phase is named; it cannot be "
            "deleted (close it with `arena admin phases set final --ends ...`)"
        )
    return _preview(f"phase {phase.name}", _submissions(session, Submission.phase == name), 0)


def remove_team(db: Database, store: ArtifactStore, name: str) -> Removal:
    with db.session() as session:
        team = teams.get_team(session, name)
        removal = team_removal(session, name)
        files = _remove_submissions(session, _submissions(session, Submission.team_id == team.id))
        session.execute(delete(ApiToken).where(ApiToken.team_id == team.id))
        session.execute(delete(Team).where(Team.id == team.id))
    _remove_files(store, files)
    return removal


def remove_phase(db: Database, store: ArtifactStore, name: str) -> Removal:
    with db.session() as session:
        removal = phase_removal(session, name)
        files = _remove_submissions(session, _submissions(session, Submission.phase == name))
        session.execute(delete(Phase).where(Phase.name == name))
    _remove_files(store, files)
    return removal


def _remove_submissions(session: Session, rows: list[Submission]) -> list[str]:
    """Delete the rows; returns the artifact prefixes to delete once they are gone."""
    active = [s.id for s in rows if s.status in ACTIVE_SUBMISSION]
    if active:
        raise Conflict(
            f"submission(s) {', '.join(map(str, active))} are still being evaluated: cancel "
            "them first (`arena admin submissions cancel ID`); nothing was deleted"
        )
    ids = [s.id for s in rows]
    if not ids:
        return []
    runs = list(
        session.scalars(select(EvaluationRun.id).where(EvaluationRun.submission_id.in_(ids)))
    )
    trainings = list(
        session.scalars(select(TrainingJob.id).where(TrainingJob.submission_id.in_(ids)))
    )
    prefixes = [s.upload_key.rsplit("/", 1)[0] for s in rows]
    prefixes += [f"runs/{run_id}" for run_id in runs]
    prefixes += [f"training/{training_id}" for training_id in trainings]
    session.execute(delete(Score).where(Score.run_id.in_(runs)))
    session.execute(delete(SeedSetScore).where(SeedSetScore.submission_id.in_(ids)))
    session.execute(delete(ScenarioResult).where(ScenarioResult.run_id.in_(runs)))
    session.execute(delete(EvaluationRun).where(EvaluationRun.id.in_(runs)))
    session.execute(delete(TrainingJob).where(TrainingJob.id.in_(trainings)))
    session.execute(delete(Submission).where(Submission.id.in_(ids)))
    bump_leaderboard(session)
    return prefixes


def _remove_files(store: ArtifactStore, prefixes: list[str]) -> None:
    # After the rows' transaction: a failure here leaves only unreachable files, never rows
    # pointing at missing ones (and the database store writes in a transaction of its own).
    for prefix in prefixes:
        store.delete_prefix(prefix)
