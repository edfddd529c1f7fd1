"""Importer for NGSIM-style vehicle trajectory CSV (US-101 / I-80 layout) into the replay format.

NGSIM columns used: ``Vehicle_ID``, ``Frame_ID`` (0.1 s frames), ``Local_X`` (lateral position of
the front centre from the left edge of the road, increasing to the right, feet), ``Local_Y``
(longitudinal position of the front centre along the direction of travel, feet), ``v_Length``,
``v_Width`` (feet), ``v_Vel`` (ft/s), ``Lane_ID``. Extra columns are ignored.

Map frame: x along the road (= Local_Y), y to the left (= -Local_X), both in metres, shifted by
``origin``; positions are moved from the front centre to the vehicle centre. Headings come from
successive centre positions (0 along +x, counter-clockwise positive); a vehicle that does not move
keeps its previous heading. NGSIM data is real recorded traffic: label it ``naturalistic``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from arena import portable_math
from arena.errors import ArenaError
from sim.trajectories import Trajectory

FOOT = 0.3048  # [m]
FRAME_S = 0.1  # [s]
REQUIRED = (
    "Vehicle_ID",
    "Frame_ID",
    "Local_X",
    "Local_Y",
    "v_Length",
    "v_Width",
    "v_Vel",
    "Lane_ID",
)
_MIN_MOVE = 0.05  # [m] smaller displacements do not define a heading


class NgsimFormatError(ArenaError, ValueError):
    pass


def headings_from_positions(x: np.ndarray, y: np.ndarray, initial: float = 0.0) -> np.ndarray:
    """(n,) heading [rad] of the displacement to the next position (the last repeats the one
    before); positions closer than 5 cm keep the previous heading (``initial`` at the start)."""
    dx, dy = np.diff(x), np.diff(y)
    moving = np.hypot(dx, dy) >= _MIN_MOVE
    h = np.empty(len(x))
    current = initial
    for i in range(len(x) - 1):
        if moving[i]:
            current = math.atan2(dy[i], dx[i])
        h[i] = current
    if len(x):
        h[-1] = h[-2] if len(x) > 1 else current
    return h


def read_ngsim(path: Path, origin: tuple[float, float] = (0.0, 0.0)) -> list[Trajectory]:
    """Trajectories of every vehicle in the file; time 0 is the file's first frame. A vehicle with
    missing frames keeps its longest run of consecutive frames."""
    rows: dict[str, list[tuple[int, float, float, float]]] = {}
    dims: dict[str, tuple[float, float]] = {}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or ())]
        if missing:
            raise NgsimFormatError(f"{path}: missing NGSIM columns {', '.join(missing)}")
        for n, row in enumerate(reader, start=2):
            try:
                vid = str(int(float(row["Vehicle_ID"])))
                rows.setdefault(vid, []).append(
                    (
                        int(float(row["Frame_ID"])),
                        float(row["Local_X"]) * FOOT,
                        float(row["Local_Y"]) * FOOT,
                        float(row["v_Vel"]) * FOOT,
                    )
                )
                dims[vid] = (float(row["v_Length"]) * FOOT, float(row["v_Width"]) * FOOT)
            except ValueError as exc:
                raise NgsimFormatError(f"{path}:{n}: {exc}") from exc
    if not rows:
        return []
    first_frame = min(r[0] for values in rows.values() for r in values)
    out = []
    for vid, values in sorted(rows.items(), key=lambda kv: int(kv[0])):
        arr = np.array(sorted(set(values)), dtype=float)
        arr = _longest_run(arr)
        length, width = dims[vid]
        front_x = arr[:, 2] + origin[0]
        front_y = -arr[:, 1] + origin[1]
        heading = headings_from_positions(front_x, front_y)
        out.append(
            Trajectory(
                vehicle_id=vid,
                time=np.round((arr[:, 0] - first_frame) * FRAME_S, 1),
                x=front_x - 0.5 * length * portable_math.cos(heading),
                y=front_y - 0.5 * length * portable_math.sin(heading),
                heading=heading,
                speed=arr[:, 3],
                length=length,
                width=width,
            )
        )
    return out


# NGSIM's optional ``v_Class`` column: 1 motorcycle, 2 automobile, 3 truck.
VEHICLE_CLASSES = {1: "motorcycle", 2: "car", 3: "truck"}


def ngsim_types(path: Path) -> dict[str, str]:
    """Each vehicle's CommonRoad obstacle type by its ``v_Class``; empty when the file has no
    such column (its vehicles are cars)."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if "v_Class" not in (reader.fieldnames or ()):
            return {}
        try:
            return {
                str(int(float(row["Vehicle_ID"]))): VEHICLE_CLASSES.get(
                    int(float(row["v_Class"])), "unknown"
                )
                for row in reader
            }
        except ValueError as exc:
            raise NgsimFormatError(f"{path}: v_Class is not a vehicle class: {exc}") from exc


def _longest_run(arr: np.ndarray) -> np.ndarray:
    """Rows of the longest run of consecutive frame numbers (column 0)."""
    breaks = np.flatnonzero(np.diff(arr[:, 0]) != 1) + 1
    runs = np.split(arr, breaks)
    return max(runs, key=len)
