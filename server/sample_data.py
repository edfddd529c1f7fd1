"""Scored submissions written straight into the database, as if a worker had evaluated them: the
data of the service tests and of the leaderboard's load benchmark."""

from __future__ import annotations

from datetime import datetime, timedelta

from evaluator.scoring import MetricSamples
from server.core.db import Database
from server.models import EvaluationRun, Score, Submission, utcnow
from server.services import evaluation
from server.status import RunStatus, SubmissionStatus
from server.tracks import Track

METRICS = ("completion", "time", "humanness", "rules")


def seed_scored(
    db: Database,
    team_id: int,
    metrics: tuple[float, float, float, float],
    *,
    track: Track = Track.freestyle,
    created_at: datetime | None = None,
    method_name: str = "method",
    families: dict | None = None,
    status: SubmissionStatus = SubmissionStatus.scored,
    phase: str = "final",
    interval: tuple[float, float] | None = None,
    samples: MetricSamples | None = None,
) -> int:
    """A submission with one scored run and its score (completion interval ``interval``,
    per-episode values ``samples``), as if a worker had evaluated it."""
    created_at = created_at or utcnow()
    with db.session() as session:
        submission = Submission(
            team_id=team_id,
            phase=phase,
            track=track,
            method_name=method_name,
            file_sha256="0" * 64,
            file_size=1,
            upload_key="submissions/none/upload.zip",
            status=status,
            created_at=created_at,
            started_at=created_at + timedelta(seconds=1),
        )
        session.add(submission)
        session.flush()
        run = EvaluationRun(
            submission_id=submission.id,
            attempt=1,
            status=RunStatus.scored,
            suite_dir="/nonexistent",
            manifest_sha256="0" * 64,
            episode_count=1,
            scoring_profile="driving-smarts-2022",
        )
        session.add(run)
        session.flush()
        session.add(
            Score(
                run_id=run.id,
                profile="driving-smarts-2022",
                families=families or {},
                completion_low=interval[0] if interval else None,
                completion_high=interval[1] if interval else None,
                samples=samples.to_json() if samples is not None else None,
                **dict(zip(METRICS, metrics, strict=True)),
            )
        )
        evaluation.bump_leaderboard(session)
        return submission.id
