"""Results drawn, not only tabled: small SVG charts rendered on the server (no script library),
sized for a 390 px phone and scaled up on a desktop (``max-width: 100%``).

Every text in them goes through :func:`html.escape` and every figure through
:mod:`arena.figures`, the one way a figure is written anywhere.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from html import escape

from arena.figures import METRICS, interval_text, metric_text

WIDTH = 360  # [px of the viewBox] fits a 390 px phone's content box
_LABEL = 12  # [px] font size of labels and values
_PANEL = WIDTH // len(METRICS)  # one metric's panel in a family's row
_BAR = 8  # [px] a bar's height


@dataclass(frozen=True)
class Figure:
    """The values a chart draws for one family: the submission's, and the leaderboard's median
    (None where nothing was measured)."""

    values: Mapping[str, float | None]
    median: Mapping[str, float | None]


def family_medians(boards: Sequence[Mapping[str, Mapping[str, float | None]]]) -> dict:
    """Each family's median of each metric over the leaderboard's entries (``boards``: every
    entry's families, family -> metric -> value); None where no entry measured it."""
    medians: dict[str, dict[str, float | None]] = {}
    for family in sorted({family for families in boards for family in families}):
        medians[family] = {}
        for metric in METRICS:
            values = [
                families[family][metric]
                for families in boards
                if family in families and families[family][metric] is not None
            ]
            medians[family][metric] = statistics.median(values) if values else None
    return medians


def _scale(figures: Mapping[str, Figure], metric: str) -> float:
    """The largest value a metric's bars reach: completion's is 1 (a fraction); the others'
    the largest value or median shown, so the longest bar fills its panel."""
    if metric == "completion":
        return 1.0
    shown = [
        value
        for figure in figures.values()
        for value in (figure.values.get(metric), figure.median.get(metric))
        if value is not None
    ]
    return max(shown, default=0.0) or 1.0


def results_chart(
    completion: float, interval: tuple[float, float] | None, figures: Mapping[str, Figure]
) -> str:
    """A scored submission's results as one SVG: completion with its 95% interval as a bar on
    the 0..1 axis, then per family its four metrics beside the leaderboard's median."""
    parts, height = [], 0
    if interval is not None:
        drawn, height = _interval(completion, *interval)
        parts.append(drawn)
    if figures:
        drawn, rows = _families(figures)
        parts.append(f'<g transform="translate(0,{height})">{drawn}</g>')
        height += rows
    said = (
        "completion and its 95% interval; the four metrics per family beside the leaderboard median"
    )
    return (
        f'<svg class="chart results-chart" role="img" viewBox="0 0 {WIDTH} {height}" '
        f'width="{WIDTH}" xmlns="http://www.w3.org/2000/svg" aria-label="{said}">'
        f"<title>{said}</title>{''.join(parts)}</svg>"
    )


def _families(figures: Mapping[str, Figure]) -> tuple[str, int]:
    """Per family, its four metrics as bars beside the leaderboard's median (a dark tick), each
    metric on its own scale; errors, so a shorter bar is better."""
    row = 2 * _LABEL + _BAR + 14
    height = 34 + row * len(figures)
    scales = {metric: _scale(figures, metric) for metric in METRICS}
    parts = [
        f'<text x="{column * _PANEL}" y="{_LABEL}" class="label head">{escape(metric)}</text>'
        for column, metric in enumerate(METRICS)
    ]
    parts.append(
        f'<text x="0" y="{2 * _LABEL + 4}" class="note">bar: this submission · tick: leaderboard '
        "median · shorter is better</text>"
    )
    for index, (family, figure) in enumerate(figures.items()):
        top = 34 + row * index
        parts.append(f'<text x="0" y="{top + _LABEL}" class="label">{escape(family)}</text>')
        for column, metric in enumerate(METRICS):
            parts.append(_metric_bar(figure, metric, scales[metric], column * _PANEL, top))
    return "".join(parts), height


def _metric_bar(figure: Figure, metric: str, scale: float, left: int, top: int) -> str:
    span = _PANEL - 10
    y = top + _LABEL + 4
    value, median = figure.values.get(metric), figure.median.get(metric)
    parts = [f'<rect x="{left}" y="{y}" width="{span}" height="{_BAR}" class="track"/>']
    if value is not None:
        width = round(span * min(value / scale, 1.0), 1)
        parts.append(
            f'<rect x="{left}" y="{y}" width="{width}" height="{_BAR}" class="bar">'
            f"<title>{escape(metric)}: {metric_text(metric, value)}</title></rect>"
        )
    if median is not None:
        x = round(left + span * min(median / scale, 1.0), 1)
        parts.append(
            f'<line x1="{x}" x2="{x}" y1="{y - 3}" y2="{y + _BAR + 3}" class="median">'
            f"<title>leaderboard median: {metric_text(metric, median)}</title></line>"
        )
    parts.append(
        f'<text x="{left}" y="{y + _BAR + _LABEL}" class="value">'
        f"{metric_text(metric, value)}</text>"
    )
    return "".join(parts)


def _interval(completion: float, low: float, high: float) -> tuple[str, int]:
    """Completion on its 0..1 axis: the 95% interval as a bar, the value a dot on it."""
    span = WIDTH - 20

    def x(value: float) -> float:
        return round(10 + span * min(max(value, 0.0), 1.0), 1)

    said = f"completion {metric_text('completion', completion)}, 95% interval " + interval_text(
        low, high
    )
    return (
        f'<g class="interval" aria-label="{escape(said)}"><title>{escape(said)}</title>'
        f'<text x="0" y="{_LABEL}" class="label head">completion, 95% interval</text>'
        f'<line x1="10" x2="{10 + span}" y1="28" y2="28" class="axis"/>'
        f'<rect x="{x(low)}" y="22" width="{round(x(high) - x(low), 1)}" height="12" rx="6" '
        'class="range"/>'
        f'<circle cx="{x(completion)}" cy="28" r="4" class="position"/>'
        f'<text x="10" y="50" class="value">0</text>'
        f'<text x="{10 + span}" y="50" class="value" text-anchor="end">1</text>'
        f'<text x="{WIDTH // 2}" y="50" class="value" text-anchor="middle">'
        f"{escape(said)}</text></g>",
        64,
    )


def curves_chart(seeds: Mapping[int, Sequence], *, live: bool) -> str:
    """Training curves (:class:`evaluator.training.metrics.Curve` per seed): one panel per
    metric name, a line per seed over its steps; ``live`` while a seed still trains."""
    names = sorted({curve.name for curves in seeds.values() for curve in curves})
    panel, top_gap = 120, 34
    height = top_gap + max(len(names), 1) * panel
    status = "training: updated as train.py writes" if live else "trained"
    parts = [
        f'<text x="0" y="{_LABEL}" class="label head">training curves ({status})</text>',
        f'<text x="0" y="{2 * _LABEL + 4}" class="note">{len(seeds)} seed(s): '
        + " · ".join(
            f'<tspan class="seed-{seed % 4}">seed {seed}</tspan>' for seed in sorted(seeds)
        )
        + "</text>",
    ]
    if not names:
        parts.append(
            f'<text x="0" y="{top_gap + _LABEL}" class="value">nothing logged yet: train.py '
            "appends step,name,value lines to $ARENA_MODEL_DIR/training_metrics.csv</text>"
        )
    for index, name in enumerate(names):
        curves = {
            seed: curve for seed, found in seeds.items() for curve in found if curve.name == name
        }
        parts.append(_curve_panel(name, curves, top_gap + index * panel, panel - 24))
    said = f"training curves of {len(seeds)} seed(s): {', '.join(names) or 'none yet'}"
    return (
        f'<svg class="chart curves-chart" role="img" viewBox="0 0 {WIDTH} {height}" '
        f'width="{WIDTH}" xmlns="http://www.w3.org/2000/svg" aria-label="{escape(said)}">'
        f"<title>{escape(said)}</title>{''.join(parts)}</svg>"
    )


def _curve_panel(name: str, curves: Mapping[int, object], top: int, height: int) -> str:
    steps = [step for curve in curves.values() for step in curve.steps]
    values = [value for curve in curves.values() for value in curve.values]
    first, last = min(steps), max(steps)
    low, high = min(values), max(values)
    left, right = 52, WIDTH - 6
    plot_top, plot_bottom = top + _LABEL + 6, top + height

    def x(step: int) -> float:
        return round(
            left + (right - left) * ((step - first) / (last - first) if last > first else 1.0), 1
        )

    def y(value: float) -> float:
        share = (value - low) / (high - low) if high > low else 0.5
        return round(plot_bottom - (plot_bottom - plot_top) * share, 1)

    parts = [
        f'<text x="0" y="{top + _LABEL}" class="label">{escape(name)}</text>',
        f'<line x1="{left}" x2="{right}" y1="{plot_bottom}" y2="{plot_bottom}" class="axis"/>',
        f'<text x="{left - 4}" y="{plot_top + 8}" class="value" text-anchor="end">'
        f"{_short(high)}</text>",
        f'<text x="{left - 4}" y="{plot_bottom}" class="value" text-anchor="end">'
        f"{_short(low)}</text>",
        f'<text x="{right}" y="{plot_bottom + _LABEL + 2}" class="value" text-anchor="end">'
        f"step {last}</text>",
    ]
    for seed, curve in sorted(curves.items()):
        points = " ".join(
            f"{x(step)},{y(value)}" for step, value in zip(curve.steps, curve.values, strict=True)
        )
        parts.append(
            f'<polyline points="{points}" class="curve seed-{seed % 4}"><title>seed {seed}, '
            f"{escape(name)}: {_short(curve.values[-1])} at step {curve.steps[-1]}</title>"
            "</polyline>"
        )
    return "".join(parts)


def _short(value: float) -> str:
    """A logged value in a few characters (any magnitude a loss or a reward takes)."""
    return f"{value:.4g}"
