"""The submission page's results drawn (:mod:`server.charts`): the team's own scored
submission beside the median of the leaderboard it is ranked on."""

from __future__ import annotations

from sqlalchemy.orm import Session

from arena.figures import METRICS
from server.charts import Figure, family_medians, results_chart
from server.models import Submission
from server.services import submissions
from server.services.errors import Conflict
from server.services.leaderboard import LeaderboardCache


def results_svg(session: Session, cache: LeaderboardCache, submission: Submission) -> str:
    """Completion with its interval and the four metrics per family beside the leaderboard's
    median of the submission's phase and track; Conflict until it is scored. Only what its
    team already sees: its per-family figures (a hidden phase's too) and the public board."""
    detail = submissions.detail(session, submission)
    if detail.metrics is None:
        raise Conflict(f"submission {submission.id} is {submission.status}: nothing to draw yet")
    board = cache.get(submission.track, submission.phase).board
    medians = family_medians(
        [
            {family: values.model_dump() for family, values in entry.families.items()}
            for entry in board.entries
        ]
    )
    figures = {
        family: Figure(
            values={metric: getattr(values, metric) for metric in METRICS},
            median=medians.get(family, {}),
        )
        for family, values in sorted(detail.families.items())
    }
    interval = detail.completion_interval
    return results_chart(
        detail.metrics.completion,
        None if interval is None else (interval.low, interval.high),
        figures,
    )
