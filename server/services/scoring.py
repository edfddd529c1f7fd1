"""Scores from stored scenario results: the same code path for a finished run and a re-score."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from evaluator.scoring import (
    AgentSummary,
    EpisodeScore,
    RecordError,
    ScoringProfile,
    aggregate,
    by_family,
    load_record,
    score_episode,
    score_without_record,
)
from server.models import ScenarioResult
from server.services.errors import Conflict

# Scenario result statuses. Only success and failure are charged to the submission.
SUCCESS = "success"
FAILURE = "failure"
SIMULATOR_ERROR = "simulator_error"
INFRASTRUCTURE_ERROR = "infrastructure_error"
RUNNING = "running"
CHARGED = frozenset({SUCCESS, FAILURE})
FINISHED = frozenset({SUCCESS, FAILURE, SIMULATOR_ERROR, INFRASTRUCTURE_ERROR})


class UnscorableRecord(Conflict):
    """A stored record that scoring cannot read (ours to investigate; the run is not scored)."""


@dataclass(frozen=True)
class RunScore:
    metrics: dict[str, float]
    families: dict[str, dict[str, Any]]  # family -> the four metrics and "scenarios" (count)


def score_results(results: Iterable[ScenarioResult], profile: ScoringProfile) -> RunScore | None:
    """The four metrics over the charged results, or None if no scenario was charged."""
    charged = [result for result in results if result.status in CHARGED]
    try:
        scores = [_episode_score(result, profile) for result in charged]
    except RecordError as exc:
        raise UnscorableRecord(f"an episode record cannot be scored: {exc}") from exc
    metrics = aggregate(scores)
    if metrics is None:
        return None
    family_of = {result.scenario_id: result.family for result in charged}
    counts: dict[str, int] = {}
    for result in charged:
        counts[result.family] = counts.get(result.family, 0) + 1
    families = {
        family: family_metrics.model_dump() | {"scenarios": counts[family]}
        for family, family_metrics in by_family(scores, family_of).items()
    }
    return RunScore(metrics=metrics.model_dump(), families=families)


def _episode_score(result: ScenarioResult, profile: ScoringProfile) -> EpisodeScore:
    if result.record_path and Path(result.record_path).is_file():
        return score_episode(load_record(Path(result.record_path)), profile)
    agents = [AgentSummary(**agent) for agent in result.detail.get("agents", [])]
    return score_without_record(result.scenario_id, agents, profile)
