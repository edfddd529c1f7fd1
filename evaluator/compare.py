"""Two evaluations side by side (``arena compare``, ``arena admin compare``): the four metrics
with the completion interval and B - A paired over the scenarios both ran (with its interval and
the chance B ranks ahead), per family, and the episodes whose outcome differs.

Each side is a :class:`Side`, built from a results folder's ``summary.json`` here or from a
stored run by the service, so both commands print the same thing. A side scored over several
training seeds (Track 2) carries each seed's run: its metrics and interval are the seed set's,
the seeds' spread is shown, and the episodes are compared seed by seed (seed k of A with seed k
of B; a side of one run with each seed of the other).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field

from rich.console import Console

from arena.figures import METRICS as METRIC_NAMES
from arena.figures import interval_text, percent
from arena.figures import metric_text as value_text
from arena.terminal import print_rows
from evaluator.runner.results import stored_episodes
from evaluator.scoring import Interval, Metrics, MetricSamples, load_profile
from evaluator.scoring.seeds import Spread
from evaluator.scoring.significance import PairedDifference, paired_difference
from evaluator.summary import Summary

REACHED = "reached_goal"
METRIC_ROW_FIELDS = ("metric", "a", "b", "b_minus_a", "b_minus_a_paired_interval")


@dataclass(frozen=True)
class SeedRun:
    """One training seed's run behind a score over several seeds."""

    seed: int
    metrics: Metrics
    outcomes: Mapping[str, str]  # as Side.outcomes


@dataclass(frozen=True)
class Side:
    """One evaluation as compared."""

    label: str
    metrics: Metrics | None
    interval: Interval | None
    families: Mapping[str, Metrics]
    # Episode name (the scenario id when it ran once) -> how it ended: "reached_goal", the
    # agents' reasons joined, or the scenario's status when it was not charged. Empty over
    # several seeds: each seed's run has its own.
    outcomes: Mapping[str, str] = field(default_factory=dict)
    suite: str = ""
    seeds: tuple[SeedRun, ...] = ()  # scored over several training seeds, in seed order
    spread: Spread | None = None  # the seeds' completion errors
    # The per-episode values the metrics are built from (None: scored before they were kept).
    samples: MetricSamples | None = None


def outcome_text(reasons: list[str], status: str) -> str:
    if status != "done":
        return status
    return ", ".join(sorted(set(reasons))) or REACHED


def side_of_summary(label: str, summary: Summary) -> Side:
    outcomes = {}
    for entry in summary.scenarios:
        for key, episode in stored_episodes(entry):
            reasons = [a.reason for a in episode.agents]
            outcomes[key.name] = outcome_text(reasons, str(episode.status))
    return Side(
        label=label,
        metrics=summary.metrics,
        interval=summary.completion_interval(),
        families=summary.families,
        outcomes=outcomes,
        suite=summary.manifest_hash,
        samples=summary.metric_samples(load_profile(summary.profile.name).averaging),
    )


def metric_text(name: str, metrics: Metrics | None) -> str:
    return "-" if metrics is None else value_text(name, getattr(metrics, name))


def difference(name: str, a: Metrics | None, b: Metrics | None) -> str:
    """B minus A; metrics are errors, so a negative difference means B is better."""
    if a is None or b is None:
        return "-"
    x, y = getattr(a, name), getattr(b, name)
    if x is None or y is None:
        return "-"
    return value_text(name, y - x, signed=True)


def paired(a: Side, b: Side) -> PairedDifference | None:
    """B - A paired over the scenarios both ran (None: a side without per-episode values, or
    different suites)."""
    if a.samples is None or b.samples is None:
        return None
    return paired_difference(a.samples, b.samples)


def metric_rows(a: Side, b: Side) -> list[tuple[str, str, str, str, str]]:
    """(metric, A, B, B - A, B - A's 95% interval paired over the shared scenarios) for the four
    metrics, then the completion interval and the chance B ranks ahead of A."""
    pair = paired(a, b)
    rows = [
        (
            name,
            metric_text(name, a.metrics),
            metric_text(name, b.metrics),
            difference(name, a.metrics, b.metrics),
            _paired_interval(pair, index, name),
        )
        for index, name in enumerate(METRIC_NAMES)
    ]
    rows.append(("completion 95% interval", _interval(a), _interval(b), "", ""))
    rows.append(("B ranks ahead of A", "", "", "", _ahead(a, b, pair)))
    return rows


def _paired_interval(pair: PairedDifference | None, index: int, name: str) -> str:
    if pair is None or pair.low[index] is None or pair.high[index] is None:
        return "-"
    low, high = pair.low[index], pair.high[index]
    text = f"[{value_text(name, low, signed=True)}, {value_text(name, high, signed=True)}]"
    if low > 0 or high < 0:
        return f"{text} {'A' if low > 0 else 'B'} better"
    return text


def _ahead(a: Side, b: Side, pair: PairedDifference | None) -> str:
    """The chance B ranks ahead of A by the hierarchy, paired, or why there is none."""
    if pair is not None:
        return f"{percent(pair.b_ahead)} of resamples over {pair.scenarios} shared scenarios"
    if a.samples is None or b.samples is None:
        return "- (a side was scored before per-episode values were kept)"
    return "- (different suites: nothing to pair)"


def _interval(side: Side) -> str:
    """A side's completion interval; a seed set's resamples seeds and scenarios both, so it
    is wider than one run's of the same agent: said, lest it be read as one run's."""
    interval = side.interval
    if interval is None:
        return "-"
    over = f" over {len(side.seeds)} seeds x scenarios" if side.seeds else ""
    return f"{interval_text(interval.low, interval.high)}{over}"


def family_rows(a: Side, b: Side) -> list[tuple[str, str, str, str, str, str]]:
    """(family, completion A, B, time A, B, completion B - A) for every family of either."""
    return [
        (
            family,
            metric_text("completion", a.families.get(family)),
            metric_text("completion", b.families.get(family)),
            metric_text("time", a.families.get(family)),
            metric_text("time", b.families.get(family)),
            difference("completion", a.families.get(family), b.families.get(family)),
        )
        for family in sorted(set(a.families) | set(b.families))
    ]


def differing_outcomes(a: Side, b: Side) -> list[tuple[str, str, str]]:
    """(episode, outcome in A, outcome in B) where they differ; "-" where one did not run it."""
    return _differing(a.outcomes, b.outcomes)


def _differing(a: Mapping[str, str], b: Mapping[str, str]) -> list[tuple[str, str, str]]:
    names = sorted(set(a) | set(b))
    rows = [(name, a.get(name, "-"), b.get(name, "-")) for name in names]
    return [row for row in rows if row[1] != row[2]]


def seeded(a: Side, b: Side) -> bool:
    """Whether either side was scored over several training seeds."""
    return bool(a.seeds or b.seeds)


def spread_rows(a: Side, b: Side) -> list[tuple[str, str, str]]:
    """(what, A, B): the number of seeds and their completion spread."""

    def count(side: Side) -> str:
        return str(len(side.seeds)) if side.seeds else "1 (one run)"

    def spread(side: Side) -> str:
        if side.spread is None:
            return "-"
        s = side.spread
        return (
            f"{value_text('completion', s.low)} to {value_text('completion', s.high)} "
            f"(std {value_text('completion', s.std)})"
        )

    return [("training seeds", count(a), count(b)), ("seeds' completion", spread(a), spread(b))]


@dataclass(frozen=True)
class SeedPair:
    """A run of A beside a run of B: the same training seed, or a side of one run (seed None)
    beside each seed of the other."""

    seed_a: int | None
    seed_b: int | None
    completion_a: str
    completion_b: str
    completion_b_minus_a: str
    differing: list[tuple[str, str, str]]  # (episode, A, B)


def seed_pairs(a: Side, b: Side) -> list[SeedPair]:
    """Each seed's run of A beside the same seed's of B (a seed only one side trained is beside
    nothing: "-"); a side of one run beside each seed of the other."""
    if a.seeds and b.seeds:
        seeds = sorted({run.seed for run in a.seeds} | {run.seed for run in b.seeds})
        keys = [(seed, seed) for seed in seeds]
    else:
        keys = [
            (run.seed if a.seeds else None, run.seed if b.seeds else None)
            for run in a.seeds or b.seeds
        ]
    pairs = []
    for key_a, key_b in keys:
        run_a, run_b = _run_of(a, key_a), _run_of(b, key_b)
        metrics_a = run_a.metrics if run_a else None
        metrics_b = run_b.metrics if run_b else None
        pairs.append(
            SeedPair(
                seed_a=key_a if run_a else None,
                seed_b=key_b if run_b else None,
                completion_a=metric_text("completion", metrics_a),
                completion_b=metric_text("completion", metrics_b),
                completion_b_minus_a=difference("completion", metrics_a, metrics_b),
                differing=_differing(run_a.outcomes, run_b.outcomes) if run_a and run_b else [],
            )
        )
    return pairs


def _run_of(side: Side, seed: int | None) -> SeedRun | None:
    """The side's run for ``seed``: its one run when it has no seeds (as seed -1), None for a
    seed it did not train."""
    if not side.seeds:
        return SeedRun(-1, side.metrics, side.outcomes) if side.metrics is not None else None
    return next((run for run in side.seeds if run.seed == seed), None)


def _seed_text(seed: int | None, side: Side) -> str:
    if seed is None:
        return "-" if side.seeds else "its run"
    return str(seed)


def comparison_document(a: Side, b: Side) -> dict:
    """The comparison as JSON (``--json``, the organisers' REST route): the rows of the tables,
    and over training seeds each side's seeds and the pairs of runs."""
    document = {
        "a": a.label,
        "b": b.label,
        "metrics": [
            dict(
                zip(("metric", "a", "b", "b_minus_a", "b_minus_a_paired_interval"), r, strict=True)
            )
            for r in metric_rows(a, b)
        ],
        "paired": _paired_json(paired(a, b)),
        "families": [
            dict(
                zip(
                    (
                        "family",
                        "completion_a",
                        "completion_b",
                        "time_a",
                        "time_b",
                        "completion_b_minus_a",
                    ),
                    r,
                    strict=True,
                )
            )
            for r in family_rows(a, b)
        ],
        "differing_outcomes": [
            dict(zip(("episode", "a", "b"), r, strict=True)) for r in differing_outcomes(a, b)
        ],
    }
    if seeded(a, b):
        document["seeds"] = {
            "a": _spread_json(a),
            "b": _spread_json(b),
            "pairs": [
                {
                    "seed_a": pair.seed_a,
                    "seed_b": pair.seed_b,
                    "completion_a": pair.completion_a,
                    "completion_b": pair.completion_b,
                    "completion_b_minus_a": pair.completion_b_minus_a,
                    "differing_outcomes": [
                        dict(zip(("episode", "a", "b"), r, strict=True)) for r in pair.differing
                    ],
                }
                for pair in seed_pairs(a, b)
            ],
        }
    return document


def print_comparison(console: Console, a: Side, b: Side, *, as_json: bool = False) -> None:
    """The three tables: metrics (with B - A, its interval paired over the shared scenarios and
    the chance B ranks ahead), per family, and the episodes whose outcome differs."""
    if as_json:
        sys.stdout.write(json.dumps(comparison_document(a, b), indent=2) + "\n")
        return
    console.print(f"A: {a.label}", markup=False, highlight=False)
    console.print(f"B: {b.label}", markup=False, highlight=False)
    if a.suite and b.suite and a.suite != b.suite:
        console.print(
            "[yellow]the two ran on different suites: per-scenario rows compare different "
            "scenarios where ids repeat[/]"
        )
    print_rows(
        console,
        ("metric", "A", "B", "B - A", "B - A 95% interval (paired)"),
        metric_rows(a, b),
        title="metrics (errors: smaller is better; B - A < 0: B is better; the interval "
        "resamples the scenarios both ran, the same draws for both)",
        numeric=("A", "B", "B - A"),
    )
    print_rows(
        console,
        ("family", "completion A", "completion B", "time A", "time B", "completion B - A"),
        family_rows(a, b),
        title="per family",
        numeric=("completion A", "completion B", "time A", "time B", "completion B - A"),
    )
    if seeded(a, b):
        _print_seeds(console, a, b)
        return
    differing = differing_outcomes(a, b)
    if differing:
        print_rows(
            console,
            ("episode", "A", "B"),
            differing,
            title=f"{len(differing)} episode(s) ended differently",
        )
    else:
        console.print("every episode ended the same way in both")


def _paired_json(pair: PairedDifference | None) -> dict | None:
    """B - A paired over the shared scenarios, as numbers (None: nothing to pair)."""
    if pair is None:
        return None
    return {
        "scenarios": pair.scenarios,
        "b_ranks_ahead": pair.b_ahead,
        **{
            name: {"b_minus_a": pair.difference[i], "low": pair.low[i], "high": pair.high[i]}
            for i, name in enumerate(METRIC_NAMES)
        },
    }


def _spread_json(side: Side) -> dict | None:
    """A side's seeds as JSON: None for a side of one run."""
    if not side.seeds or side.spread is None:
        return None
    return {
        "count": len(side.seeds),
        "completion_min": side.spread.low,
        "completion_max": side.spread.high,
        "completion_std": side.spread.std,
        "per_seed": [
            {"seed": run.seed, **{name: getattr(run.metrics, name) for name in METRIC_NAMES}}
            for run in side.seeds
        ],
    }


def _print_seeds(console: Console, a: Side, b: Side) -> None:
    """Over training seeds: the seeds' spread, each pair of runs' completion, and per pair the
    episodes that ended differently."""
    print_rows(console, ("", "A", "B"), spread_rows(a, b), title="training seeds")
    pairs = seed_pairs(a, b)
    print_rows(
        console,
        ("seed A", "seed B", "completion A", "completion B", "B - A", "episodes ended differently"),
        [
            (
                _seed_text(p.seed_a, a),
                _seed_text(p.seed_b, b),
                p.completion_a,
                p.completion_b,
                p.completion_b_minus_a,
                str(len(p.differing)),
            )
            for p in pairs
        ],
        title="per seed (seed k of A beside seed k of B)"
        if a.seeds and b.seeds
        else "per seed (the run of one side beside each seed of the other)",
        numeric=("completion A", "completion B", "B - A", "episodes ended differently"),
    )
    rows = [
        (_seed_text(p.seed_a, a), _seed_text(p.seed_b, b), *row)
        for p in pairs
        for row in p.differing
    ]
    if rows:
        print_rows(
            console,
            ("seed A", "seed B", "episode", "A", "B"),
            rows,
            title=f"{len(rows)} episode(s) ended differently",
        )
    else:
        console.print("every episode ended the same way in each pair of runs")
