"""How sure a completion figure is: a bootstrap confidence interval.

Two evaluations of agents that are equally good differ by chance (which scenarios the suite
drew, which traffic each episode met). The interval resamples both and says how far that
chance alone moves the completion error. Whether two entries are tied is not read from their
intervals overlapping (two entries paired over one suite can be told apart with overlapping
intervals): that is the rank ranges' question (:mod:`evaluator.scoring.significance`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

RESAMPLES = 2000
LEVEL = 0.95
# Fixed, so the same results always give the same interval.
BOOTSTRAP_SEED = 20221128
# Resamples drawn at once: bounds memory to about CHUNK x scenarios x episodes values.
_CHUNK = 100


@dataclass(frozen=True)
class Interval:
    low: float
    high: float


def bootstrap_interval(
    per_scenario: Sequence[Sequence[float]],
    *,
    resamples: int = RESAMPLES,
    level: float = LEVEL,
    seed: int = BOOTSTRAP_SEED,
) -> Interval:
    """Percentile interval of the mean over scenarios of each scenario's mean over its episodes.

    ``per_scenario[s]`` holds scenario ``s``'s value in each of its episodes (one value for a
    scenario run once). Each resample draws the scenarios with replacement, then, within each
    drawn scenario, its episodes with replacement (a two-stage bootstrap).
    """
    if not per_scenario or any(len(values) == 0 for values in per_scenario):
        raise ValueError("bootstrap_interval needs at least one scenario, each with an episode")
    counts = np.array([len(values) for values in per_scenario])
    table = np.zeros((len(per_scenario), counts.max()))  # (scenarios, most episodes)
    for row, values in zip(table, per_scenario, strict=True):
        row[: len(values)] = values
    rng = np.random.default_rng(seed)
    means = []
    for start in range(0, resamples, _CHUNK):
        size = min(_CHUNK, resamples - start)
        drawn = rng.integers(0, len(counts), size=(size, len(counts)))  # (size, scenarios)
        n = counts[drawn][..., None]  # episodes of each drawn scenario
        # Episode draws in 0..n-1 for each slot; slots beyond a scenario's n are masked out.
        episode = np.floor(rng.random((size, len(counts), table.shape[1])) * n).astype(int)
        slot = np.arange(table.shape[1])
        values = np.where(slot < n, table[drawn[..., None], episode], 0.0)
        means.append((values.sum(axis=-1) / n[..., 0]).mean(axis=-1))
    tail = 100 * (1 - level) / 2
    low, high = np.percentile(np.concatenate(means), [tail, 100 - tail])
    return Interval(float(low), float(high))
