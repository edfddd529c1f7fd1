"""Which leaderboard differences are real: rank ranges and the chance one entry beats another.

The leaderboard orders entries by the scoring spec's hierarchy (completion, then time, then
humanness, then rules). That order is a fact about one evaluation; whether it would hold on
another draw of scenarios and traffic is a statistical question. Each entry's metrics are
recomputed on bootstrap resamples of its scenarios and, within each, of its episodes (the same
two-stage bootstrap as :func:`evaluator.scoring.interval.bootstrap_interval`), and in each
resample the two entries are compared by the hierarchy itself. The fraction of resamples one
entry comes out ahead is the probability that it beats the other.

Entries evaluated on the same suite are resampled *paired*: one draw of scenarios (and of episode
indices) serves every entry, so a scenario that is hard for everyone moves every entry alike and
only the differences between agents remain. Entries on different suites are drawn independently.

An entry's rank range runs from one plus the number of entries that beat it significantly to the
number of entries minus those it beats significantly: entries whose difference is not
significant share ranks.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from evaluator.scoring.interval import BOOTSTRAP_SEED, LEVEL, RESAMPLES

# One row per episode: what the suite metrics are built from (evaluator/scoring/episode.py).
SAMPLE_FIELDS = ("failure", "time", "humanness_sum", "rules_sum", "weight")
# Resamples drawn at once: bounds memory to about CHUNK x scenarios x episodes x fields values.
_CHUNK = 100
# Episode resamples kept per scenario; each drawn scenario takes one of them at random.
EPISODE_POOL = 256
# Decimals metric values are compared to in a resample.
_DECIMALS = 9


@dataclass(frozen=True)
class MetricSamples:
    """One evaluation's per-episode values, each scenario a ``(episodes, 5)`` array of
    :data:`SAMPLE_FIELDS`; ``suite`` (the suite's manifest hash) says which entries are paired."""

    suite: str
    scenarios: Mapping[str, np.ndarray]

    def to_json(self) -> dict:
        return {
            "suite": self.suite,
            "scenarios": {sid: rows.tolist() for sid, rows in sorted(self.scenarios.items())},
        }

    @classmethod
    def from_json(cls, data: Mapping) -> MetricSamples:
        scenarios = {
            sid: np.asarray(rows, dtype=float).reshape(-1, len(SAMPLE_FIELDS))
            for sid, rows in data["scenarios"].items()
        }
        if not scenarios or any(len(rows) == 0 for rows in scenarios.values()):
            raise ValueError("metric samples need at least one scenario, each with an episode")
        return cls(suite=str(data["suite"]), scenarios=scenarios)

    def metrics(self) -> np.ndarray:
        """The four metrics (completion, time, humanness, rules) the samples give without
        resampling: each scenario the mean over its episodes, humanness and rules a ratio of
        sums (NaN when no agent drove a step)."""
        means = np.array([rows.mean(axis=0) for rows in self.scenarios.values()])
        return _metrics(means.sum(axis=0)[None], np.array([len(means)]))[0]


@dataclass(frozen=True)
class RankRange:
    low: int  # best rank the entry could hold (1-based)
    high: int  # worst
    beats_next: float | None  # chance it ranks ahead of the entry just below; None for the last

    @property
    def label(self) -> str:
        return str(self.low) if self.low == self.high else f"{self.low}-{self.high}"


def _metrics(sums: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(resamples, 4) metrics from (resamples, 5) sums of scenario means over ``counts``
    scenarios."""
    with np.errstate(invalid="ignore", divide="ignore"):
        completion = sums[:, 0] / counts
        time = sums[:, 1] / counts
        weight = np.where(sums[:, 4] > 0, sums[:, 4], np.nan)
        return np.stack([completion, time, sums[:, 2] / weight, sums[:, 3] / weight], axis=1)


def _seed(suite: str, seed: int) -> list[int]:
    return [seed, int.from_bytes(hashlib.sha256(suite.encode()).digest()[:8], "big")]


def replicates(
    entries: Sequence[MetricSamples], *, resamples: int = RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> list[np.ndarray]:
    """Each entry's four metrics on each bootstrap resample, a ``(resamples, 4)`` array; NaN
    where a resample drew none of the entry's scenarios (humanness and rules also where no agent
    drove). The same entries always give the same replicates."""
    out: list[np.ndarray | None] = [None] * len(entries)
    by_suite: dict[str, list[int]] = {}
    for position, entry in enumerate(entries):
        by_suite.setdefault(entry.suite, []).append(position)
    for suite, members in by_suite.items():
        universe = sorted({sid for m in members for sid in entries[m].scenarios})
        column = {sid: i for i, sid in enumerate(universe)}
        most = max(len(rows) for m in members for rows in entries[m].scenarios.values())
        rng = np.random.default_rng(_seed(suite, seed))
        # Stage two, drawn once per suite as uniforms so entries with as many episodes of a
        # scenario draw the same episode indices (paired): a pool of episode resamples per
        # scenario, of which each drawn scenario then takes one.
        pool_uniform = rng.random((len(universe), EPISODE_POOL, most))
        tables = [_table(entries[m], column, pool_uniform) for m in members]
        parts: list[list[np.ndarray]] = [[] for _ in members]
        for start in range(0, resamples, _CHUNK):
            size = min(_CHUNK, resamples - start)
            # Stage one: the scenarios, shared by every entry of the suite (paired).
            drawn = rng.integers(0, len(universe), size=(size, len(universe)))
            pick = rng.integers(0, EPISODE_POOL, size=(size, len(universe)))
            for part, table in zip(parts, tables, strict=True):
                part.append(_resampled(table, drawn, pick))
        for m, part in zip(members, parts, strict=True):
            out[m] = np.concatenate(part)
    return out  # type: ignore[return-value]


@dataclass(frozen=True)
class _Table:
    row_of: np.ndarray  # (universe,) the entry's row of each universe scenario, -1 if absent
    pool: np.ndarray  # (rows, EPISODE_POOL, 5) means over resampled episodes of each scenario


def _table(entry: MetricSamples, column: Mapping[str, int], pool_uniform: np.ndarray) -> _Table:
    rows = list(entry.scenarios.values())
    counts = np.array([len(r) for r in rows])
    values = np.zeros((len(rows), counts.max(), len(SAMPLE_FIELDS)))
    row_of = np.full(len(column), -1)
    columns = np.empty(len(rows), int)
    for i, (sid, r) in enumerate(entry.scenarios.items()):
        values[i, : len(r)] = r
        columns[i] = column[sid]
        row_of[column[sid]] = i
    slots = values.shape[1]
    n = counts[:, None, None]  # (rows, 1, 1)
    episode = np.floor(pool_uniform[columns, :, :slots] * n).astype(int)  # (rows, pool, slots)
    picked = values[np.arange(len(rows))[:, None, None], episode]  # (rows, pool, slots, 5)
    mask = (np.arange(slots) < n)[..., None]
    return _Table(row_of, np.where(mask, picked, 0.0).sum(axis=2) / n)


def _resampled(table: _Table, drawn: np.ndarray, pick: np.ndarray) -> np.ndarray:
    rows = table.row_of[drawn]  # (size, universe)
    present = rows >= 0
    means = table.pool[np.where(present, rows, 0), pick]  # (size, universe, 5)
    sums = (means * present[..., None]).sum(axis=1)
    return _metrics(sums, present.sum(axis=1))


def _standing(reps: np.ndarray) -> np.ndarray:
    """``(entries, resamples)`` places of stacked replicates ``(entries, resamples, 4)`` in each
    resample by the scoring hierarchy (0 best; entries tied on every metric share a place): an
    entry that drove ahead of one that did not, then completion, time, humanness, rules."""
    # Rounded, so two means of different numbers that are equal but for the last bit tie, as
    # the ranking's exact comparison finds values computed alike equal.
    values = np.round(reps, _DECIMALS)
    drove = ~np.isnan(values[..., 2])
    keys = [
        np.where(drove, values[..., 3], 0.0),
        np.where(drove, values[..., 2], 0.0),
        values[..., 1],
        values[..., 0],
        (~drove).astype(float),
    ]  # least significant first, as np.lexsort wants
    order = np.lexsort([k.T for k in keys], axis=-1)  # (resamples, entries)
    sorted_keys = np.stack([np.take_along_axis(k.T, order, axis=-1) for k in keys])
    new_place = np.any(sorted_keys[:, :, 1:] != sorted_keys[:, :, :-1], axis=0)
    places_sorted = np.concatenate(
        [np.zeros((len(order), 1), int), np.cumsum(new_place, axis=-1)], axis=-1
    )
    places = np.empty_like(places_sorted)
    np.put_along_axis(places, order, places_sorted, axis=-1)
    return places.T


def beat_matrix(reps: Sequence[np.ndarray | None]) -> np.ndarray:
    """``p[i, j]``: the chance entry i ranks ahead of entry j by the scoring hierarchy, over the
    resamples (a full tie is half a win; so is a resample where either drew none of its
    scenarios); NaN where either has no replicates."""
    n = len(reps)
    p = np.full((n, n), np.nan)
    known = [i for i, r in enumerate(reps) if r is not None]
    if len(known) < 2:
        return p
    stacked = np.stack([reps[i] for i in known])  # (known, resamples, 4)
    places = _standing(stacked)
    defined = ~np.isnan(stacked[..., 0])
    for row, i in enumerate(known):
        both = defined[row] & defined
        wins = np.where(both, (places[row] < places) + 0.5 * (places[row] == places), 0.5)
        p[i, known] = wins.mean(axis=-1)
        p[i, i] = np.nan
    return p


def rank_ranges(
    samples: Sequence[MetricSamples | None],
    *,
    level: float = LEVEL,
    resamples: int = RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> list[RankRange]:
    """Rank ranges of entries given in leaderboard order (best first). Entry j beats entry i
    significantly when it comes out ahead in at least ``1 - (1 - level) / 2`` of the resamples
    (a two-sided test at ``level``). An entry without samples (scored before they were kept)
    cannot be compared: it keeps its own rank and no range crosses it."""
    known = [i for i, s in enumerate(samples) if s is not None]
    reps: list[np.ndarray | None] = [None] * len(samples)
    for i, r in zip(
        known,
        replicates([samples[i] for i in known], resamples=resamples, seed=seed),
        strict=True,
    ):
        reps[i] = r
    raw = beat_matrix(reps)
    n = len(samples)
    # Entries on either side of one without samples are decided in the leaderboard's order.
    unknown = np.array([s is None for s in samples])
    segment = np.where(unknown, n + 1 + np.arange(n), np.cumsum(unknown))
    order = np.arange(n)[:, None] < np.arange(n)[None, :]  # order[j, i]: j is above i
    p = np.where(segment[:, None] == segment[None, :], raw, order.astype(float))
    threshold = 1 - (1 - level) / 2
    ranges = []
    for i in range(n):
        above, below = p[:, i] >= threshold, p[i] >= threshold
        above[i] = below[i] = False
        beats_next = None if i + 1 == n or np.isnan(raw[i, i + 1]) else float(raw[i, i + 1])
        ranges.append(
            RankRange(
                low=min(i + 1, 1 + int(above.sum())),
                high=max(i + 1, n - int(below.sum())),
                beats_next=beats_next,
            )
        )
    return ranges
