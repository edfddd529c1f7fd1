"""A submission trained with several seeds: its score over them, how sure that score is, and
how far apart the seeds landed.

Training is itself random: the same ``train.py`` run with another seed gives another model, and
one training run can be lucky. A phase that trains each submission with N seeds evaluates each
model on the same suite; the submission's metrics are the means over the seeds. The interval of
its completion resamples both sources of chance at once: the seeds (which trainings happened)
and the scenarios (which the suite drew), crossed (every drawn seed on every drawn scenario).
The spread says how much the seeds alone differ.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evaluator.scoring.interval import BOOTSTRAP_SEED, LEVEL, RESAMPLES, Interval
from evaluator.scoring.significance import SAMPLE_FIELDS, MetricSamples

METRICS = ("completion", "time", "humanness", "rules")
_FAILURE = SAMPLE_FIELDS.index("failure")
# Resamples drawn at once: bounds memory to about CHUNK x seeds x scenarios values.
_CHUNK = 100


@dataclass(frozen=True)
class Spread:
    """The seeds' own completion errors: lowest, highest and their standard deviation
    (``ddof=1``; 0 for one seed)."""

    low: float
    high: float
    std: float


def seed_interval(
    table: Sequence[Sequence[float]] | np.ndarray,
    *,
    resamples: int = RESAMPLES,
    level: float = LEVEL,
    seed: int = BOOTSTRAP_SEED,
) -> Interval:
    """Percentile interval of the mean of ``table`` (seeds x scenarios: each seed's completion
    error on each scenario, the mean over its episodes). Each resample draws the seeds with
    replacement and, independently, the scenarios with replacement, and averages the drawn
    seeds over the drawn scenarios."""
    values = np.asarray(table, dtype=float)
    if values.ndim != 2 or values.size == 0:
        raise ValueError("seed_interval needs a table of at least one seed and one scenario")
    seeds, scenarios = values.shape
    rng = np.random.default_rng(seed)
    means = []
    for start in range(0, resamples, _CHUNK):
        size = min(_CHUNK, resamples - start)
        rows = rng.integers(0, seeds, size=(size, seeds))
        columns = rng.integers(0, scenarios, size=(size, scenarios))
        drawn = values[rows[:, :, None], columns[:, None, :]]  # (size, seeds, scenarios)
        means.append(drawn.mean(axis=(1, 2)))
    tail = 100 * (1 - level) / 2
    low, high = np.percentile(np.concatenate(means), [tail, 100 - tail])
    return Interval(float(low), float(high))


def spread(completions: Sequence[float]) -> Spread:
    values = np.asarray(completions, dtype=float)
    if values.size == 0:
        raise ValueError("spread needs at least one seed")
    std = float(values.std(ddof=1)) if values.size > 1 else 0.0
    return Spread(low=float(values.min()), high=float(values.max()), std=std)


def completion_table(samples: Sequence[MetricSamples]) -> np.ndarray:
    """Seeds x scenarios: each seed's completion error per scenario (the mean over its
    episodes), scenarios in id order. Every seed must cover the same scenarios."""
    ids = sorted(samples[0].scenarios) if samples else []
    if not ids or any(sorted(s.scenarios) != ids for s in samples):
        raise ValueError("every seed needs the same, non-empty set of scenarios")
    return np.array([[s.scenarios[sid][:, _FAILURE].mean() for sid in ids] for s in samples])


def pooled_samples(samples: Sequence[MetricSamples]) -> MetricSamples:
    """One evaluation of the seeds together: each scenario's episodes of every seed, as the
    leaderboard's rank ranges resample them. Their metrics are the means over the seeds when
    the seeds ran the same episodes."""
    if not samples or len({s.suite for s in samples}) != 1:
        raise ValueError("pooled samples need at least one seed, all on the same suite")
    completion_table(samples)  # the same scenarios in each
    return MetricSamples(
        suite=samples[0].suite,
        scenarios={
            sid: np.concatenate([s.scenarios[sid] for s in samples])
            for sid in sorted(samples[0].scenarios)
        },
    )


def _mean(values: Sequence[float | None]) -> float | None:
    """The mean of the measured values; None when no seed measured it (no agent drove)."""
    measured = [v for v in values if v is not None]
    return float(np.mean(measured)) if measured else None


def mean_metrics(per_seed: Sequence[Mapping[str, float | None]]) -> dict[str, float | None]:
    """Each of the four metrics averaged over the seeds that measured it."""
    if not per_seed:
        raise ValueError("mean_metrics needs at least one seed")
    return {name: _mean([metrics[name] for metrics in per_seed]) for name in METRICS}


def mean_families(per_seed: Sequence[Mapping[str, Mapping[str, Any]]]) -> dict[str, dict]:
    """Per family, the four metrics averaged over the seeds (and the family's scenario count,
    the same in each)."""
    families = sorted({family for seed in per_seed for family in seed})
    merged = {}
    for family in families:
        rows = [seed[family] for seed in per_seed if family in seed]
        merged[family] = {**mean_metrics(rows), "scenarios": rows[0].get("scenarios")}
    return merged
