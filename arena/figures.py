"""How a score's numbers are written, wherever they are shown: the pages, the API's CSV, the
admin CLI, ``arena compare`` and ``arena evaluate``.

One rule, so that one value never reads 0.5313 on one page and 0.5312 on another: time to one
decimal, every other metric (and an interval's bounds) to four, rounded half away from zero on
the float's exact binary value. That is the rule of JavaScript's ``Number.prototype.toFixed``,
which the browser pages use (``fmt`` in ``server/static/app.js``), where Python's ``format``
rounds such halves to even (``f"{0.53125:.4f}"`` is ``0.5312``); completion values are
fractions of scenarios, so exact halves are common.
"""

from __future__ import annotations

from decimal import ROUND_HALF_UP, Decimal

# The four metrics, in the scoring hierarchy's order.
METRICS = ("completion", "time", "humanness", "rules")
# Shown where nothing was measured (no agent drove a step).
UNMEASURED = "—"


def fixed(value: float, decimals: int, *, signed: bool = False) -> str:
    """``value`` to ``decimals`` places, halves away from zero (as ``toFixed``); ``signed``:
    with its sign always (a difference)."""
    text = str(Decimal(value).quantize(Decimal(1).scaleb(-decimals), rounding=ROUND_HALF_UP))
    if text.startswith("-") and not text.strip("-0."):
        text = text[1:]  # -0.0000 is no difference
    return f"+{text}" if signed and not text.startswith("-") else text


def decimals(metric: str) -> int:
    return 1 if metric == "time" else 4


def metric_text(metric: str, value: float | None, *, signed: bool = False) -> str:
    """One metric's value (or a difference of two: ``signed``), "—" where nothing was measured."""
    if value is None:
        return UNMEASURED
    return fixed(value, decimals(metric), signed=signed)


def interval_text(low: float, high: float, metric: str = "completion") -> str:
    return f"[{metric_text(metric, low)}, {metric_text(metric, high)}]"


def percent(chance: float) -> str:
    """A chance (0..1) as a percentage to one decimal: ``97.5%``."""
    return f"{fixed(100 * chance, 1)}%"
