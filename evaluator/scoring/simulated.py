"""Per-episode values of a simulated agent, for the significance tests and the load benchmark of
the leaderboard (its rank ranges resample them): no simulation, drawn from chances."""

from __future__ import annotations

import numpy as np

from evaluator.scoring.significance import MetricSamples

MAX_STEPS = 800.0


def simulated(
    rng: np.random.Generator,
    failure: float | np.ndarray,
    *,
    scenarios: int = 40,
    episodes: int = 3,
    time: float = 300.0,
    humanness: float = 0.5,
    drove: bool = True,
    suite: str = "suite",
) -> MetricSamples:
    """The per-episode values of a simulated agent failing each mission with chance ``failure``
    (one per scenario, or the same in every scenario), finishing in about ``time`` steps when it
    succeeds; odd scenarios are reactive and run ``episodes`` times."""
    chance = np.broadcast_to(failure, (scenarios,))
    table = {}
    for s in range(scenarios):
        k = episodes if s % 2 else 1
        failed = (rng.random(k) < chance[s]).astype(float)
        steps = np.where(failed > 0, MAX_STEPS, rng.normal(time, 20.0, k))
        weight = rng.integers(100, 300, k).astype(float) if drove else np.zeros(k)
        h = rng.normal(humanness, 0.05, k) * weight
        table[f"s{s:03d}"] = np.stack([failed, steps, h, 0.1 * weight, weight], axis=1)
    return MetricSamples(suite, table)
