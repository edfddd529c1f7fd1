"""Two evaluations side by side (``arena compare``, ``arena admin compare``): the four metrics
with the completion interval, per family, and the episodes whose outcome differs.

Each side is a :class:`Side`, built from a results folder's ``summary.json`` here or from a
stored run by the service, so both commands print the same thing.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field

from rich.console import Console

from arena.terminal import print_rows
from evaluator.runner.results import stored_episodes
from evaluator.scoring import Interval, Metrics
from evaluator.summary import Summary

METRIC_NAMES = ("completion", "time", "humanness", "rules")
REACHED = "reached_goal"


@dataclass(frozen=True)
class Side:
    """One evaluation as compared."""

    label: str
    metrics: Metrics | None
    interval: Interval | None
    families: Mapping[str, Metrics]
    # Episode name (the scenario id when it ran once) -> how it ended: "reached_goal", the
    # agents' reasons joined, or the scenario's status when it was not charged.
    outcomes: Mapping[str, str] = field(default_factory=dict)
    suite: str = ""


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
    )


def metric_text(name: str, metrics: Metrics | None) -> str:
    if metrics is None:
        return "-"
    value = getattr(metrics, name)
    if value is None:
        return "—"  # no agent drove a step: nothing measured
    return f"{value:.1f}" if name == "time" else f"{value:.4f}"


def difference(name: str, a: Metrics | None, b: Metrics | None) -> str:
    """B minus A; metrics are errors, so a negative difference means B is better."""
    if a is None or b is None:
        return "-"
    x, y = getattr(a, name), getattr(b, name)
    if x is None or y is None:
        return "-"
    delta = y - x
    return f"{delta:+.1f}" if name == "time" else f"{delta:+.4f}"


def metric_rows(a: Side, b: Side) -> list[tuple[str, str, str, str]]:
    """(metric, A, B, B - A) for the four metrics, then the completion interval."""
    rows = [
        (
            name,
            metric_text(name, a.metrics),
            metric_text(name, b.metrics),
            difference(name, a.metrics, b.metrics),
        )
        for name in METRIC_NAMES
    ]
    rows.append(
        (
            "completion 95% interval",
            _interval(a.interval),
            _interval(b.interval),
            _overlap(a.interval, b.interval),
        )
    )
    return rows


def _interval(interval: Interval | None) -> str:
    return "-" if interval is None else f"[{interval.low:.4f}, {interval.high:.4f}]"


def _overlap(a: Interval | None, b: Interval | None) -> str:
    if a is None or b is None:
        return "-"
    if a.high < b.low:
        return "A better (no overlap)"
    if b.high < a.low:
        return "B better (no overlap)"
    return "overlap: may be chance"


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
    names = sorted(set(a.outcomes) | set(b.outcomes))
    rows = [(name, a.outcomes.get(name, "-"), b.outcomes.get(name, "-")) for name in names]
    return [row for row in rows if row[1] != row[2]]


def print_comparison(console: Console, a: Side, b: Side, *, as_json: bool = False) -> None:
    """The three tables: metrics (with B - A and whether the intervals overlap), per family,
    and the episodes whose outcome differs."""
    if as_json:
        document = {
            "a": a.label,
            "b": b.label,
            "metrics": [
                dict(zip(("metric", "a", "b", "b_minus_a"), r, strict=True))
                for r in metric_rows(a, b)
            ],
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
        sys.stdout.write(json.dumps(document, indent=2) + "\n")
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
        ("metric", "A", "B", "B - A"),
        metric_rows(a, b),
        title="metrics (errors: smaller is better; B - A < 0: B is better)",
        numeric=("A", "B", "B - A"),
    )
    print_rows(
        console,
        ("family", "completion A", "completion B", "time A", "time B", "completion B - A"),
        family_rows(a, b),
        title="per family",
        numeric=("completion A", "completion B", "time A", "time B", "completion B - A"),
    )
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
