"""Training curves: the metrics file a Track 2 ``train.py`` may write, read bounded and neutralised.

``train.py`` appends lines ``step,name,value`` to ``$ARENA_MODEL_DIR/training_metrics.csv``
(``step`` an integer 0 or more, ``name`` 1 to 40 of ``A-Z a-z 0-9 _ . / -``, ``value`` a finite
number), e.g. ``120,loss,0.4137``. The service reads it while the training runs and shows each
name as a curve (docs/training.md, "Training curves").

The file is the team's: it is read on the host only as text, never followed through a link, only
when it is a regular file, at most its last :data:`MAX_BYTES`; a line that is not exactly that
shape is skipped, never interpreted. What is kept is bounded too: :data:`MAX_SERIES` names (the
first ones met) of at most :data:`MAX_POINTS` points each, thinned evenly (the last point kept).
The file is left out of the trained output's archive (:mod:`evaluator.training.model`), so a
curve's timing never makes two seeds' models differ.
"""

from __future__ import annotations

import math
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

METRICS_FILE = "training_metrics.csv"
MAX_BYTES = 256 * 1024  # the tail of the file read
MAX_SERIES = 8
MAX_POINTS = 200  # per series, after thinning
_LINE = re.compile(r"(\d{1,12}),([A-Za-z0-9_./-]{1,40}),([-+0-9.eE]{1,32})")


@dataclass(frozen=True)
class Curve:
    """One metric's points, in step order."""

    name: str
    steps: tuple[int, ...]
    values: tuple[float, ...]

    def to_json(self) -> dict:
        return {"name": self.name, "steps": list(self.steps), "values": list(self.values)}

    @classmethod
    def from_json(cls, data: dict) -> Curve:
        return cls(str(data["name"]), tuple(data["steps"]), tuple(data["values"]))


def read_curves(output: Path) -> list[Curve]:
    """The curves of ``output``'s metrics file (none when it is missing, a link, not a regular
    file, or holds no line of the documented shape)."""
    return parse_curves(_tail(Path(output) / METRICS_FILE))


def _tail(path: Path) -> str:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:  # missing, a link, unreadable
        return ""
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):  # a folder, a FIFO, a device
        os.close(fd)
        return ""
    with os.fdopen(fd, "rb") as file:
        start = max(0, info.st_size - MAX_BYTES)
        file.seek(start)
        data = file.read(MAX_BYTES)
    text = data.decode("utf-8", errors="replace")
    # A read from the middle of the file starts inside a line: that part is not a line.
    return text.split("\n", 1)[1] if start else text


def parse_curves(text: str) -> list[Curve]:
    """The documented lines of ``text`` as curves (each name's points in step order, a step
    given twice keeping its last value), bounded as the module says."""
    series: dict[str, dict[int, float]] = {}
    for line in text.splitlines():
        match = _LINE.fullmatch(line.strip())
        if match is None:
            continue
        step, name, raw = match.groups()
        try:
            value = float(raw)
        except ValueError:
            continue
        if not math.isfinite(value):
            continue
        if name not in series:
            if len(series) == MAX_SERIES:
                continue
            series[name] = {}
        series[name][int(step)] = value
    return [_thinned(name, points) for name, points in series.items()]


def _thinned(name: str, points: dict[int, float]) -> Curve:
    steps = sorted(points)
    if len(steps) > MAX_POINTS:
        every = len(steps) / MAX_POINTS
        kept = [steps[int(i * every)] for i in range(MAX_POINTS - 1)] + [steps[-1]]
        steps = kept
    return Curve(name, tuple(steps), tuple(points[step] for step in steps))
