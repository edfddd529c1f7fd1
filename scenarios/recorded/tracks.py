"""Which recorded vehicles are one vehicle: CommonRoad cuts one recording into scenes ``X_1``,
``X_2``, ... that share most of their vehicles, under other obstacle ids and with each scene's
clock starting at 0; a file may also be another moved, turned or delayed (a rotated tutorial
copy, a georeferenced export). Files say nothing of this, so vehicles are matched by the shape of
what they did: their motion relative to themselves, never their absolute positions.

A track's *poses* are its moving frames as (frame, x, y, heading), rounded as a manifest stores
them. Each frame that has poses :data:`WINDOW` and twice and three times :data:`WINDOW` frames
later gives a *shape token*: the distances between those four positions (how far it drove in each
of three half-seconds, and how much it turned), which no rigid motion and no change of clock alters.
Tracks sharing at least :data:`MIN_TOKENS` tokens at one constant frame offset are candidates,
kept when the positions of every frame they share at that offset are one rigid motion apart, to
:data:`MAX_RESIDUAL_M`, over at least :data:`MIN_SHARED_POSES` frames; then they are one vehicle
if that shape says enough or a neighbour agrees (:class:`TrackIndex`). Two vehicles following one
lane drive the same line but not the same speeds, and a stopped vehicle's poses are left out
(any two queue at one stop line).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from arena import portable_math
from sim.trajectories import Trajectory

STEP_S = 0.1  # [s]
MOVING_SPEED = 1.0  # [m/s] slower frames are not evidence of identity
WINDOW = 5  # frames between the positions of a shape token (0.5 s)
_DISTANCE_CELL = 0.1  # [m] a token's distances are rounded to this
MIN_TOKENS = 3  # shared tokens at one frame offset that make two tracks a candidate pair
MIN_SHARED_POSES = 15  # frames two tracks of one vehicle share at least (1.5 s)
MAX_RESIDUAL_M = 0.1  # [m] farthest a shared frame's position may be from the rigid fit
SHAPED_M = 0.5  # [m] a segment this far from a straight line at one speed has a shape of its own

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


def _arrays(poses: Iterable[Sequence[float]]) -> tuple[np.ndarray, np.ndarray]:
    """(frames (n,) int, positions (n, 2)) of ``poses``, in frame order."""
    rows = sorted((int(p[0]), float(p[1]), float(p[2])) for p in poses)
    if not rows:
        return np.zeros(0, int), np.zeros((0, 2))
    arr = np.array(rows)
    return arr[:, 0].astype(int), arr[:, 1:]


def _tokens(frames: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, list[tuple]]:
    """The frames that start a shape token, and their tokens."""
    index = {int(f): i for i, f in enumerate(frames)}
    starts = [
        (f, [index[int(f)], *(index.get(int(f) + k * WINDOW) for k in (1, 2, 3))]) for f in frames
    ]
    starts = [(f, rows) for f, rows in starts if None not in rows]
    if not starts:
        return np.zeros(0, int), []
    rows = np.array([r for _, r in starts])
    p = xy[rows]  # (m, 4, 2)
    sides = np.stack(
        [np.hypot(*(p[:, b] - p[:, a]).T) for a, b in ((0, 1), (1, 2), (2, 3), (0, 2), (1, 3))],
        axis=1,
    )
    cells = np.round(sides / _DISTANCE_CELL).astype(int)
    return np.array([f for f, _ in starts]), [tuple(c) for c in cells.tolist()]


def _rigid_residual(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance [m] between ``b`` and ``a`` moved by the rotation and translation that
    fit it best (least squares; no mirroring: in the plane the best angle has a closed form)."""
    ca, cb = a - a.mean(axis=0), b - b.mean(axis=0)
    angle = portable_math.arctan2(
        np.sum(ca[:, 0] * cb[:, 1] - ca[:, 1] * cb[:, 0]),
        np.sum(ca[:, 0] * cb[:, 0] + ca[:, 1] * cb[:, 1]),
    )
    c, s = portable_math.cos(angle), portable_math.sin(angle)
    moved_x, moved_y = c * ca[:, 0] - s * ca[:, 1], s * ca[:, 0] + c * ca[:, 1]
    return float(np.hypot(moved_x - cb[:, 0], moved_y - cb[:, 1]).max())


def _line_deviation(frames: np.ndarray, xy: np.ndarray) -> float:
    """Farthest [m] ``xy`` lies from the best constant-velocity straight line through it: how
    much shape a segment has (none when it cruises straight at one speed)."""
    design = np.stack([np.ones(len(frames)), frames - frames[0]], axis=1).astype(float)
    fit, *_ = np.linalg.lstsq(design, xy, rcond=None)
    return float(np.hypot(*(design @ fit - xy).T).max())


Key = tuple[Hashable, str]  # (scene, vehicle id)


@dataclass(frozen=True)
class _Pair:
    """A query vehicle whose shared frames are one rigid motion from an indexed one's."""

    vehicle: str
    key: Key
    offset: int  # indexed frame - query frame
    frames: np.ndarray  # (n,) the shared frames, on the indexed track's clock
    mine: np.ndarray  # (n, 2) the query's positions at the shared frames
    theirs: np.ndarray  # (n, 2) the indexed track's


class TrackIndex:
    """Scenes' tracks, queried with another scene's for the vehicles that are one.

    A pair of tracks of one shape is one vehicle when the shape says enough on its own (it
    deviates :data:`SHAPED_M` from a straight line at one speed), or when another pair of the two
    scenes at the same clock offset is moved by the very same rigid motion: the vehicles' places
    relative to each other agree too. Two cars cruising straight at one speed have one shape, but
    not one neighbourhood."""

    def __init__(self) -> None:
        self._by_token: dict[tuple, list[tuple[Key, int]]] = defaultdict(list)
        self._tracks: dict[Key, tuple[np.ndarray, np.ndarray]] = {}

    def add(self, scene: Hashable, tracks: Mapping[str, Iterable[Sequence[float]]]) -> None:
        """Index every track of ``scene`` (vehicle id -> poses)."""
        for vehicle, poses in tracks.items():
            key = (scene, vehicle)
            frames, xy = _arrays(poses)
            self._tracks[key] = (frames, xy)
            starts, tokens = _tokens(frames, xy)
            for frame, token in zip(starts.tolist(), tokens, strict=True):
                self._by_token[token].append((key, frame))

    def same_vehicles(self, tracks: Mapping[str, Iterable[Sequence[float]]]) -> dict[str, set[Key]]:
        """Per vehicle of a scene's ``tracks``, the indexed (scene, vehicle)s it is."""
        pairs = [pair for vehicle, poses in tracks.items() for pair in self._pairs(vehicle, poses)]
        alike: dict[tuple, list[_Pair]] = defaultdict(list)  # by indexed scene and clock offset
        for pair in pairs:
            alike[(pair.key[0], pair.offset)].append(pair)
        out: dict[str, set[Key]] = {}
        for pair in pairs:
            if _line_deviation(pair.frames, pair.mine) >= SHAPED_M or any(
                _one_motion(pair, other) for other in alike[(pair.key[0], pair.offset)]
            ):
                out.setdefault(pair.vehicle, set()).add(pair.key)
        return out

    def _pairs(self, vehicle: str, poses: Iterable[Sequence[float]]) -> list[_Pair]:
        frames, xy = _arrays(poses)
        starts, tokens = _tokens(frames, xy)
        votes: Counter = Counter()
        for frame, token in zip(starts.tolist(), tokens, strict=True):
            for key, other in self._by_token.get(token, ()):
                votes[(key, other - frame)] += 1
        out = []
        for (key, offset), n in votes.items():
            if n < MIN_TOKENS:
                continue
            other_frames, other_xy = self._tracks[key]
            shared, mine, theirs = np.intersect1d(
                frames + offset, other_frames, assume_unique=True, return_indices=True
            )
            if len(shared) >= MIN_SHARED_POSES:
                pair = _Pair(vehicle, key, offset, shared, xy[mine], other_xy[theirs])
                if _rigid_residual(pair.mine, pair.theirs) <= MAX_RESIDUAL_M:
                    out.append(pair)
        return out


def _one_motion(a: _Pair, b: _Pair) -> bool:
    """Whether ``b``, a pair of the same two scenes at the same clock offset, of two other
    vehicles, is moved by ``a``'s rigid motion too."""
    if a.vehicle == b.vehicle or a.key[1] == b.key[1]:
        return False
    both = _rigid_residual(np.concatenate([a.mine, b.mine]), np.concatenate([a.theirs, b.theirs]))
    return both <= 2 * MAX_RESIDUAL_M


def recording_location(scene_name: str) -> str:
    """The recording a CommonRoad benchmark id belongs to: ``USA_Peach-3_2_T-1`` ->
    ``USA_Peach-3`` (country_location-map, then the scene number and the task id). Other names
    are their own recording."""
    parts = scene_name.split("_")
    if len(parts) >= 3 and parts[2].isdigit():
        return "_".join(parts[:2])
    return scene_name
