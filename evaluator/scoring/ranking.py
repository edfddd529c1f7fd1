"""Hierarchical ranking (scoring spec): (completion, time, humanness, rules) ascending, full ties
to the earlier submission, entries where no agent drove a step after every entry that drove, and
unscored entries after every scored one."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, TypeVar

from evaluator.scoring.metrics import Metrics

RankedT = TypeVar("RankedT")


def rank_key(metrics: Metrics | None, submitted_at: Any) -> tuple:
    if metrics is None:
        return (1, (), submitted_at)
    if not metrics.drove:
        return (0, (1, metrics.completion, metrics.time), submitted_at)
    values = (metrics.completion, metrics.time, metrics.humanness, metrics.rules)
    return (0, (0, *values), submitted_at)


def rank(
    entries: Iterable[RankedT],
    *,
    metrics: Callable[[RankedT], Metrics | None],
    submitted_at: Callable[[RankedT], Any],
) -> list[RankedT]:
    """Entries best first. ``submitted_at`` must be comparable (a datetime, or a sequence id)."""
    return sorted(entries, key=lambda entry: rank_key(metrics(entry), submitted_at(entry)))
