"""The training-metrics file: what train.py writes is read bounded and neutralised (a link is
not followed, only a regular file's tail is read, a line of any other shape is skipped)."""

from __future__ import annotations

import os

from evaluator.training.metrics import (
    MAX_BYTES,
    MAX_POINTS,
    MAX_SERIES,
    METRICS_FILE,
    parse_curves,
    read_curves,
)


def test_the_documented_lines_become_curves_and_nothing_else_does():
    text = "\n".join(
        [
            "1,loss,0.5",
            "2,loss,0.25",
            "1,reward,-3e2",
            "2,loss,0.2",  # a step again: its last value
            "3,loss,nan",  # not a finite number
            "4,loss,inf",
            "x,loss,1",
            "5,<script>,1",
            "6,loss,1,2",
            "7,loss,0x10",
            "  8,loss,0.1  ",
        ]
    )
    curves = {curve.name: curve for curve in parse_curves(text)}
    assert curves["loss"].steps == (1, 2, 8) and curves["loss"].values == (0.5, 0.2, 0.1)
    assert curves["reward"].values == (-300.0,)
    assert set(curves) == {"loss", "reward"}


def test_what_is_kept_is_bounded():
    many = "\n".join(f"{step},m{step % (MAX_SERIES + 3)},{step}" for step in range(5000))
    curves = parse_curves(many)
    assert len(curves) == MAX_SERIES
    assert all(len(curve.steps) <= MAX_POINTS for curve in curves)
    long = parse_curves("\n".join(f"{step},loss,{step}" for step in range(10_000)))[0]
    assert len(long.steps) == MAX_POINTS and long.steps[-1] == 9_999  # thinned, the last kept


def test_only_a_regular_files_tail_is_read_never_through_a_link(tmp_path):
    secret = tmp_path / "secret"
    secret.write_text("1,leaked,42\n")
    output = tmp_path / "output"
    output.mkdir()
    (output / METRICS_FILE).symlink_to(secret)
    assert read_curves(output) == []
    (output / METRICS_FILE).unlink()
    os.mkfifo(output / METRICS_FILE)  # would block a plain open
    assert read_curves(output) == []
    (output / METRICS_FILE).unlink()
    (output / METRICS_FILE).mkdir()
    assert read_curves(output) == []
    (output / METRICS_FILE).rmdir()
    assert read_curves(output) == []  # none written
    # Far past the bound: only the tail is read, its first (cut) line dropped.
    lines = [f"{step},loss,{step}" for step in range(200_000)]
    (output / METRICS_FILE).write_text("\n".join(lines) + "\n")
    assert (output / METRICS_FILE).stat().st_size > 4 * MAX_BYTES
    (curve,) = read_curves(output)
    assert curve.steps[-1] == 199_999 and curve.steps[0] > 150_000
