"""Suite metrics (scoring spec, "the four metrics over a set of scenarios")."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from pydantic import BaseModel, ConfigDict

from evaluator.scoring.episode import EpisodeScore


class Metrics(BaseModel):
    """The four errors; smaller is better."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    completion: float  # failures / N
    time: float  # [steps] mean of T^i
    # Means over all agent-steps (or agent-episodes, per the profile) of the humanness and rules
    # terms; None when no agent drove a step (nothing was measured: never shown as 0, the best).
    humanness: float | None
    rules: float | None

    @property
    def drove(self) -> bool:
        return self.humanness is not None


def aggregate(scores: Iterable[EpisodeScore]) -> Metrics | None:
    """Metrics over a set of scenario scores; None for an empty set (nothing to rank)."""
    scores = list(scores)
    if not scores:
        return None
    n = len(scores)
    weight = sum(score.weight for score in scores)
    return Metrics(
        completion=sum(score.failure for score in scores) / n,
        time=sum(score.time for score in scores) / n,
        humanness=sum(score.humanness_sum for score in scores) / weight if weight else None,
        rules=sum(score.rules_sum for score in scores) / weight if weight else None,
    )


def by_family(scores: Iterable[EpisodeScore], family_of: Mapping[str, str]) -> dict[str, Metrics]:
    """Metrics per scenario family, families in sorted order."""
    groups: dict[str, list[EpisodeScore]] = {}
    for score in scores:
        groups.setdefault(family_of[score.scenario_id], []).append(score)
    return {family: aggregate(groups[family]) for family in sorted(groups)}


def scenario_metrics(score: EpisodeScore) -> Metrics:
    return aggregate([score])
