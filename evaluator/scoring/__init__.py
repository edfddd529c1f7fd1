"""Scoring: episode records -> per-agent-step terms -> per-scenario sums -> suite metrics -> rank.

Everything here is a pure function of records and a :class:`ScoringProfile`.
"""

from evaluator.scoring.episode import (
    EpisodeScore,
    mean_score,
    score_episode,
    score_without_record,
)
from evaluator.scoring.interval import Interval, bootstrap_interval
from evaluator.scoring.metrics import Metrics, aggregate, by_family, scenario_metrics
from evaluator.scoring.profile import DEFAULT_PROFILE, ProfileError, ScoringProfile, load_profile
from evaluator.scoring.ranking import rank, rank_key
from evaluator.scoring.record import EpisodeRecord, load_record
from evaluator.scoring.significance import MetricSamples, RankRange, rank_ranges

__all__ = [
    "DEFAULT_PROFILE",
    "EpisodeRecord",
    "EpisodeScore",
    "Interval",
    "MetricSamples",
    "Metrics",
    "ProfileError",
    "RankRange",
    "ScoringProfile",
    "aggregate",
    "bootstrap_interval",
    "by_family",
    "load_profile",
    "load_record",
    "mean_score",
    "rank",
    "rank_key",
    "rank_ranges",
    "scenario_metrics",
    "score_episode",
    "score_without_record",
]
