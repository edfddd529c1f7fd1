"""Recorded vehicle trajectories: the replay file format shared by recorders, importers and the
simulator.

A trajectory file is CSV with a header row and one row per vehicle and frame::

    vehicle_id,time,x,y,heading,speed,length,width

``time`` [s] is a multiple of the step length (0.1 s); ``x``, ``y`` [m] are the vehicle centre in
the map frame; ``heading`` [rad] is 0 along +x, counter-clockwise positive; ``speed`` [m/s];
``length``, ``width`` [m]. Rows are sorted by vehicle id, then time. A vehicle exists from its
first frame to its last; frames are consecutive.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.geometry import box_corners

COLUMNS = ("vehicle_id", "time", "x", "y", "heading", "speed", "length", "width")


@dataclass(frozen=True)
class Trajectory:
    vehicle_id: str
    time: np.ndarray  # (n,) [s]
    x: np.ndarray  # (n,) [m]
    y: np.ndarray  # (n,) [m]
    heading: np.ndarray  # (n,) [rad]
    speed: np.ndarray  # (n,) [m/s]
    length: float  # [m]
    width: float  # [m]

    def corners(self, frames: np.ndarray) -> np.ndarray:
        """Corners (n, 4, 2) [m] of the vehicle's box at ``frames`` (indices into its arrays)."""
        return box_corners(
            self.x[frames], self.y[frames], self.heading[frames], self.length, self.width
        )


def read_trajectories(path: Path) -> dict[str, Trajectory]:
    """Each vehicle's trajectory, in the order vehicles first appear; a vehicle's frames sorted
    by time (stably: the file's order among equal times), its size that of its last row."""
    with open(path, newline="") as f:
        header = f.readline().rstrip("\r\n").split(",")
        if tuple(header) != COLUMNS:
            raise ValueError(f"{path}: expected columns {','.join(COLUMNS)}")
        # numpy's C reader: a replay's ~20,000 rows were most of an episode's fixed cost through
        # csv.DictReader. Its numbers are parsed as float() parses them (correctly rounded).
        lines = [line for line in f.read().splitlines() if line]  # as csv, skip blank lines
    if not lines:
        return {}
    table = {"delimiter": ",", "quotechar": '"', "comments": None, "ndmin": 1}
    try:
        ids = np.loadtxt(lines, dtype=str, usecols=0, **table).tolist()
        values = np.loadtxt(lines, dtype=np.float64, usecols=range(1, 8), **table)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    values = values.reshape(len(ids), len(COLUMNS) - 1)
    order = {vid: k for k, vid in enumerate(dict.fromkeys(ids))}
    last = {vid: row for row, vid in enumerate(ids)}
    vehicle = np.fromiter(map(order.__getitem__, ids), np.int64, len(ids))
    # By vehicle, then time; lexsort is stable, so equal times keep the file's order.
    rows = np.lexsort((values[:, 0], vehicle))
    ends = np.searchsorted(vehicle[rows], np.arange(1, len(order) + 1))
    out = {}
    for vid, part in zip(order, np.split(rows, ends[:-1]), strict=True):
        motion = values[part, :5]
        length, width = values[last[vid], 5:].tolist()
        out[vid] = Trajectory(vid, *motion.T, length, width)
    return out


def write_trajectories(path: Path, trajectories: dict[str, Trajectory] | list[Trajectory]) -> None:
    items = trajectories.values() if isinstance(trajectories, dict) else trajectories
    with open(path, "w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(COLUMNS)
        for tr in sorted(items, key=lambda tr: tr.vehicle_id):
            for t, x, y, h, v in zip(tr.time, tr.x, tr.y, tr.heading, tr.speed, strict=True):
                writer.writerow(
                    [
                        tr.vehicle_id,
                        f"{t:.1f}",
                        f"{x:.3f}",
                        f"{y:.3f}",
                        f"{h:.5f}",
                        f"{v:.3f}",
                        f"{tr.length:.2f}",
                        f"{tr.width:.2f}",
                    ]
                )
