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


def read_trajectories(path: Path) -> dict[str, Trajectory]:
    rows: dict[str, list[list[float]]] = {}
    dims: dict[str, tuple[float, float]] = {}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if tuple(reader.fieldnames or ()) != COLUMNS:
            raise ValueError(f"{path}: expected columns {','.join(COLUMNS)}")
        for row in reader:
            vid = row["vehicle_id"]
            rows.setdefault(vid, []).append(
                [float(row[c]) for c in ("time", "x", "y", "heading", "speed")]
            )
            dims[vid] = (float(row["length"]), float(row["width"]))
    out = {}
    for vid, values in rows.items():
        arr = np.asarray(values, dtype=np.float64)
        arr = arr[np.argsort(arr[:, 0], kind="stable")]
        out[vid] = Trajectory(vid, *arr.T, *dims[vid])
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
