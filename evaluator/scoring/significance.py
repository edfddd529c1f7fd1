"""Which leaderboard differences are real: rank ranges and the chance one entry beats another.

The leaderboard orders entries by the scoring spec's hierarchy (completion, then time, then
humanness, then rules). That order is a fact about one evaluation; whether it would hold on
another draw of scenarios and traffic is a statistical question. Each entry's metrics are
recomputed on bootstrap resamples of its scenarios and, within each, of its episodes (the same
two-stage bootstrap as :func:`evaluator.scoring.interval.bootstrap_interval`), and in each
resample the two entries are compared by the hierarchy itself. The fraction of resamples one
entry comes out ahead is the probability that it beats the other.

Entries evaluated on the same suite are resampled *paired*: the draws come from the suite and its
scenario ids alone, so one draw of scenarios (and of episode indices) serves every entry, a
scenario that is hard for everyone moves every entry alike, and only the differences between
agents remain. Entries on different suites are drawn independently. Within a scenario run several
times, each drawn scenario takes one of ``EPISODE_POOL`` resamples of its episodes, made once per
entry (the second stage, at the cost of one gather per resample whatever the episode count).

An entry's rank range runs from one plus the number of entries that beat it significantly to the
number of entries minus those it beats significantly: entries whose difference is not
significant share ranks. "Tied" means exactly that and nothing else: an entry is tied with the
other ranks inside its range (:attr:`RankRange.tied_with`), the one definition the leaderboard's
badge, the team's standing, the API, the CSV and the CLI all show.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from arena.figures import percent
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
    rank: int  # the entry's position on the leaderboard (1-based)
    low: int  # best rank the entry could hold
    high: int  # worst
    beats_next: float | None  # chance it ranks ahead of the entry just below; None for the last
    # False: scored before per-episode values were kept, so never compared (its rank stands).
    compared: bool = True

    @property
    def label(self) -> str:
        return str(self.low) if self.low == self.high else f"{self.low}-{self.high}"

    @property
    def tied_with(self) -> tuple[int, ...]:
        """The other ranks the entry could hold: those it is statistically tied with (none when
        its rank is certain)."""
        return tuple(r for r in range(self.low, self.high + 1) if r != self.rank)

    @property
    def statement(self) -> str:
        """The range and the chance against the entry below in words, as every view says them:
        ``could rank 1 to 2 (statistically tied with rank 2); ahead of rank 2 in 71.5% of the
        bootstrap resamples``."""
        if not self.compared:
            return (
                f"rank {self.rank}: scored before per-episode values were kept, so not compared "
                "with the others (arena admin rescore --all computes them)"
            )
        if self.tied_with:
            ranks = " and ".join(str(r) for r in self.tied_with)
            where = (
                f"could rank {self.low} to {self.high} (statistically tied with "
                f"rank{'s' if len(self.tied_with) > 1 else ''} {ranks})"
            )
        else:
            where = f"rank {self.rank} is certain (no entry statistically tied)"
        if self.beats_next is None:
            return where
        return (
            f"{where}; ahead of rank {self.rank + 1} in {percent(self.beats_next)} of the "
            "bootstrap resamples"
        )


def _metrics(sums: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(resamples, 4) metrics from (resamples, 5) sums of scenario means over ``counts``
    scenarios."""
    with np.errstate(invalid="ignore", divide="ignore"):
        completion = sums[:, 0] / counts
        time = sums[:, 1] / counts
        weight = np.where(sums[:, 4] > 0, sums[:, 4], np.nan)
        return np.stack([completion, time, sums[:, 2] / weight, sums[:, 3] / weight], axis=1)


def replicates(
    samples: MetricSamples, *, resamples: int = RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> np.ndarray:
    """The entry's four metrics on each bootstrap resample, a ``(resamples, 4)`` array
    (humanness and rules NaN where no agent drove). A pure function of the samples: the draws
    come from the suite and its scenario ids alone, so every entry on the same suite gets the
    same draws (paired) and an entry's replicates can be kept for as long as its score."""
    universe = sorted(samples.scenarios)
    key = "\n".join([samples.suite, *universe]).encode()
    stream = [seed, int.from_bytes(hashlib.sha256(key).digest()[:8], "big")]
    draws = np.random.default_rng(stream)
    pool = _episode_pool(samples, universe, np.random.default_rng([*stream, 1]))
    # (5, scenarios x pool): each field's values contiguous, so a resample's sum is a gather
    # and a sum along the last axis.
    fields = np.ascontiguousarray(pool.reshape(-1, len(SAMPLE_FIELDS)).T)
    parts = []
    for start in range(0, resamples, _CHUNK):
        size = min(_CHUNK, resamples - start)
        # Stage one, a scenario, and stage two, one of its episode resamples, in one uniform
        # draw over (scenario, pool slot) pairs.
        flat = draws.integers(0, len(universe) * EPISODE_POOL, size=(size, len(universe)))
        sums = np.stack([values[flat].sum(axis=1) for values in fields], axis=1)
        parts.append(_metrics(sums, np.array([len(universe)])))
    return np.concatenate(parts)


def _episode_pool(
    samples: MetricSamples, universe: Sequence[str], rng: np.random.Generator
) -> np.ndarray:
    """``(scenarios, EPISODE_POOL, 5)``: means of each scenario's fields over resampled
    episodes (a scenario run once: its one episode throughout). Drawn as uniforms, so entries
    with as many episodes of a scenario draw the same episode indices (paired)."""
    rows = [samples.scenarios[sid] for sid in universe]
    counts = np.array([len(r) for r in rows])
    slots = counts.max()
    uniform = rng.random((len(rows), EPISODE_POOL, slots))
    pool = np.empty((len(rows), EPISODE_POOL, len(SAMPLE_FIELDS)))
    for n in np.unique(counts):
        (members,) = np.nonzero(counts == n)
        values = np.stack([rows[i] for i in members])  # (members, n, 5)
        if n == 1:
            pool[members] = values
            continue
        episode = np.floor(uniform[members, :, :n] * n).astype(np.intp)  # (members, pool, n)
        pool[members] = values[np.arange(len(members))[:, None, None], episode].mean(axis=2)
    return pool


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
    resamples (a full tie is half a win); NaN where either has no replicates."""
    n = len(reps)
    p = np.full((n, n), np.nan)
    known = [i for i, r in enumerate(reps) if r is not None]
    if len(known) < 2:
        return p
    places = _standing(np.stack([reps[i] for i in known])).astype(np.int32)  # (known, resamples)
    resamples = places.shape[1]
    for row, i in enumerate(known[:-1]):
        later = places[row + 1 :]
        ahead = np.count_nonzero(places[row] < later, axis=-1)
        tied = np.count_nonzero(places[row] == later, axis=-1)
        chance = (ahead + 0.5 * tied) / resamples
        p[i, known[row + 1 :]] = chance
        p[known[row + 1 :], i] = 1.0 - chance
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
    reps = [None if s is None else replicates(s, resamples=resamples, seed=seed) for s in samples]
    return ranges_from_replicates(reps, level=level)


def ranges_from_replicates(
    reps: Sequence[np.ndarray | None], *, level: float = LEVEL
) -> list[RankRange]:
    """:func:`rank_ranges` from each entry's :func:`replicates` (None: no samples)."""
    raw = beat_matrix(reps)
    n = len(reps)
    # Entries on either side of one without samples are decided in the leaderboard's order.
    unknown = np.array([r is None for r in reps], dtype=bool)
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
                rank=i + 1,
                low=min(i + 1, 1 + int(above.sum())),
                high=max(i + 1, n - int(below.sum())),
                beats_next=beats_next,
                compared=not unknown[i],
            )
        )
    return ranges


@dataclass(frozen=True)
class PairedDifference:
    """B minus A over the scenarios both ran, each of the four metrics with its interval (None
    where either side measured nothing), and the chance B ranks ahead of A by the hierarchy."""

    scenarios: int  # shared scenarios the difference is taken over
    difference: tuple[float | None, ...]
    low: tuple[float | None, ...]
    high: tuple[float | None, ...]
    b_ahead: float


def paired_difference(
    a: MetricSamples,
    b: MetricSamples,
    *,
    level: float = LEVEL,
    resamples: int = RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> PairedDifference | None:
    """B - A paired over the scenarios both evaluations ran: every resample draws the same
    scenarios (and, where both ran as many episodes of a scenario, the same episode indices,
    episode ``k`` having the same traffic for both) for the two, so what is common to both
    cancels and the interval is that of the difference itself, narrower than the two
    intervals side by side. None when they ran different suites (a scenario id then names two
    different scenarios) or share no scenario."""
    shared = sorted(set(a.scenarios) & set(b.scenarios))
    if a.suite != b.suite or not shared:
        return None
    sides = [
        MetricSamples(side.suite, {sid: side.scenarios[sid] for sid in shared}) for side in (a, b)
    ]
    reps_a, reps_b = (replicates(side, resamples=resamples, seed=seed) for side in sides)
    tail = 100 * (1 - level) / 2
    with np.errstate(invalid="ignore"):
        point = sides[1].metrics() - sides[0].metrics()
        diff = reps_b - reps_a
    bounds = []
    for column in diff.T:
        measured = column[~np.isnan(column)]
        bounds.append(
            np.percentile(measured, [tail, 100 - tail]) if len(measured) else (np.nan, np.nan)
        )
    return PairedDifference(
        scenarios=len(shared),
        difference=_optional(point),
        low=_optional([low for low, _ in bounds]),
        high=_optional([high for _, high in bounds]),
        b_ahead=float(beat_matrix([reps_a, reps_b])[1, 0]),
    )


def _optional(values) -> tuple[float | None, ...]:
    return tuple(None if np.isnan(v) else float(v) for v in values)
