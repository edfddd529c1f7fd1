"""Which recorded vehicles are one vehicle: CommonRoad cuts one recording into scenes ``X_1``,
``X_2``, ... that share most of their vehicles, under other obstacle ids and with each scene's
clock starting at 0. Files say nothing of this, so vehicles are matched by what they did.

A track's *poses* are its moving frames as (frame, x, y, heading), rounded as a manifest stores
them. Two tracks are one vehicle when at least :data:`MIN_SHARED_POSES` of their poses coincide
(position to 5 cm, heading to 0.05 rad) at one constant frame offset: the same vehicle seen
through two scene clocks. Two vehicles following one lane pass the same points, but at a
varying offset, and a stopped vehicle's poses are left out (any two queue at one stop line).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence

import numpy as np

from sim.trajectories import Trajectory

STEP_S = 0.1  # [s]
MOVING_SPEED = 1.0  # [m/s] slower frames are not evidence of identity
MIN_SHARED_POSES = 5
_POSITION_CELL = 0.05  # [m]
_HEADING_CELL = 0.05  # [rad]

Pose = tuple[int, float, float, float]  # (frame, x [m], y [m], heading [rad])


def track_poses(tr: Trajectory) -> list[Pose]:
    """The moving frames of ``tr``, rounded as stored (2 decimals, 3 for heading)."""
    moving = np.abs(tr.speed) >= MOVING_SPEED
    # Speeds may be absent from a file (0): then the displacement says whether it moved.
    step = np.hypot(np.diff(tr.x, append=tr.x[-1]), np.diff(tr.y, append=tr.y[-1]))
    moving |= step >= MOVING_SPEED * STEP_S
    frames = np.round(tr.time / STEP_S).astype(int)
    return [
        (int(f), round(float(x), 2), round(float(y), 2), round(float(h), 3))
        for f, x, y, h, m in zip(frames, tr.x, tr.y, tr.heading, moving, strict=True)
        if m
    ]


def _token(pose: Sequence[float]) -> tuple[int, int, int]:
    _, x, y, h = pose
    return (round(x / _POSITION_CELL), round(y / _POSITION_CELL), round(h / _HEADING_CELL))


class TrackIndex:
    """Tracks by key (any hashable), queried for the keys of the same vehicle."""

    def __init__(self) -> None:
        self._by_token: dict[tuple[int, int, int], list[tuple[object, int]]] = defaultdict(list)

    def add(self, key: object, poses: Iterable[Sequence[float]]) -> None:
        for pose in poses:
            self._by_token[_token(pose)].append((key, int(pose[0])))

    def same_vehicle(self, poses: Iterable[Sequence[float]]) -> set:
        """Keys of the indexed tracks that are the vehicle of ``poses``."""
        offsets: Counter = Counter()
        for pose in poses:
            for key, frame in self._by_token.get(_token(pose), ()):
                offsets[(key, frame - int(pose[0]))] += 1
        return {key for (key, _), n in offsets.items() if n >= MIN_SHARED_POSES}


def recording_location(scene_name: str) -> str:
    """The recording a CommonRoad benchmark id belongs to: ``USA_Peach-3_2_T-1`` ->
    ``USA_Peach-3`` (country_location-map, then the scene number and the task id). Other names
    are their own recording."""
    parts = scene_name.split("_")
    if len(parts) >= 3 and parts[2].isdigit():
        return "_".join(parts[:2])
    return scene_name
