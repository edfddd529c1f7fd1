"""One lane of the road network: its centreline as a polyline and the lane-frame maths on it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

WAYPOINT_SPACING = 1.0  # [m] distance between consecutive waypoints along a lane
_STEPS = WAYPOINT_SPACING * np.arange(256)  # [m] offsets of a path's first points from its start
# Lanes of more centreline points than this are projected onto with numpy (one pass over all
# segments), fewer with a scalar loop; both give the same result.
_VECTOR_PROJECTION_POINTS = 16


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Wrap radians to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2 * np.pi)


@dataclass(eq=False)
class Lane:
    """A SUMO lane. ``index`` 0 is the rightmost lane of its edge; internal lanes are the
    connections inside a junction. A lane that does not allow passenger cars is a shoulder."""

    id: str
    edge_id: str
    index: int
    centreline: np.ndarray  # (n, 2) [m], in driving direction
    width: float  # [m]
    speed_limit: float  # [m/s]
    is_internal: bool
    is_shoulder: bool
    successors: list[str] = field(default_factory=list)  # lane ids reachable at the lane's end

    def __post_init__(self) -> None:
        pts = np.asarray(self.centreline, dtype=np.float64)
        if len(pts) < 2 or np.allclose(pts[0], pts[-1]):
            # Zero-length internal lanes exist; give them a tiny extent so the maths stays finite.
            pts = np.array([pts[0], pts[0] + [1e-3, 0.0]])
        self.centreline = pts
        seg = np.diff(pts, axis=0)
        self.segment_lengths = np.hypot(seg[:, 0], seg[:, 1])  # (n-1,) [m]
        self.segment_headings = np.arctan2(seg[:, 1], seg[:, 0])  # (n-1,) [rad]
        self.cumulative_s = np.concatenate([[0.0], np.cumsum(self.segment_lengths)])  # (n,) [m]
        self.length = float(self.cumulative_s[-1])  # [m]
        self._points = pts.tolist()
        self._seg_len2 = np.maximum(seg[:, 0] * seg[:, 0] + seg[:, 1] * seg[:, 1], 1e-12)
        # Contiguous copies for np.interp, which would otherwise copy each column per call.
        self._xs, self._ys = pts[:, 0].copy(), pts[:, 1].copy()
        # Segment i starts at cumulative_s[i]: searching the inner offsets gives the segment of
        # an offset directly, already within [0, n - 2] (see heading_at).
        self._inner_s = self.cumulative_s[1:-1].copy()

    def project(self, x: float, y: float) -> tuple[float, float, float]:
        """Lane coordinates of a point: (s [m] along the lane, t [m] signed lateral offset, left
        positive, heading [rad] of the lane at s)."""
        pts = self._points
        if len(pts) > _VECTOR_PROJECTION_POINTS:
            return self._project_vectorised(x, y)
        # Scalar Python: most lanes have few segments, and numpy's per-call overhead would
        # dominate.
        best = (math.inf, 0, 0.0)
        for i in range(len(pts) - 1):
            (x0, y0), (x1, y1) = pts[i], pts[i + 1]
            dx, dy = x1 - x0, y1 - y0
            rx, ry = x - x0, y - y0
            u = min(max((rx * dx + ry * dy) / max(dx * dx + dy * dy, 1e-12), 0.0), 1.0)
            d2 = (rx - dx * u) ** 2 + (ry - dy * u) ** 2
            if d2 < best[0]:
                best = (d2, i, u)
        return self._frame(best[1], best[2], x, y)

    def _project_vectorised(self, x: float, y: float) -> tuple[float, float, float]:
        """:meth:`project` for lanes of many points (curves): the same arithmetic per segment,
        and the first nearest segment wins as in the scalar loop."""
        p0, d = self.centreline[:-1], np.diff(self.centreline, axis=0)
        rx, ry = x - p0[:, 0], y - p0[:, 1]
        u = np.minimum(np.maximum((rx * d[:, 0] + ry * d[:, 1]) / self._seg_len2, 0.0), 1.0)
        ex, ey = rx - d[:, 0] * u, ry - d[:, 1] * u
        i = int(np.argmin(ex * ex + ey * ey))
        return self._frame(i, float(u[i]), x, y)

    def _frame(self, i: int, u: float, x: float, y: float) -> tuple[float, float, float]:
        (x0, y0), (x1, y1) = self._points[i], self._points[i + 1]
        seg_len = max(math.hypot(x1 - x0, y1 - y0), 1e-12)
        t = ((x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)) / seg_len
        s = float(self.cumulative_s[i]) + u * seg_len
        return s, t, float(self.segment_headings[i])

    def position_at(self, s: float | np.ndarray) -> np.ndarray:
        """Centreline point(s) at distance ``s`` [m] along the lane, (2,) or (m, 2)."""
        s = np.clip(s, 0.0, self.length)
        return np.stack(
            [
                np.interp(s, self.cumulative_s, self.centreline[:, 0]),
                np.interp(s, self.cumulative_s, self.centreline[:, 1]),
            ],
            axis=-1,
        )

    def point_at(self, s: float) -> tuple[float, float]:
        """:meth:`position_at` of one offset, as floats, without np.clip and np.stack (a controller
        and the junction match ask for single points every step)."""
        s = min(max(s, 0.0), self.length)
        cum = self.cumulative_s
        return float(np.interp(s, cum, self._xs)), float(np.interp(s, cum, self._ys))

    def heading_at(self, s: float | np.ndarray) -> float | np.ndarray:
        """Lane direction [rad] at distance ``s`` [m] along the lane."""
        i = np.clip(
            np.searchsorted(self.cumulative_s, s, side="right") - 1,
            0,
            len(self.segment_headings) - 1,
        )
        return self.segment_headings[i]

    @property
    def waypoints(self) -> list[dict]:
        """Waypoint dicts every :data:`WAYPOINT_SPACING` along the lane, from s = 0."""
        return waypoint_dicts([(self, np.arange(0.0, self.length, WAYPOINT_SPACING))])

    def waypoint_offsets(self, first_s: float, limit: int) -> tuple[np.ndarray, int]:
        """Up to ``limit`` offsets s = ``first_s`` + k * :data:`WAYPOINT_SPACING` [m], k >= 0,
        short of the lane's end; and how many such points the lane has in all.

        A path starts level with the vehicle (``first_s`` is its own s) and one crossing into
        this lane starts at the offset left over from the previous one, so the spacing stays
        even along the whole path.
        """
        first_s = max(first_s, 0.0)
        total = max(math.ceil((self.length - first_s) / WAYPOINT_SPACING - 1e-9), 0)
        count = min(limit, total)
        steps = _STEPS[:count] if count <= len(_STEPS) else WAYPOINT_SPACING * np.arange(count)
        return first_s + steps, total

    def waypoints_from(self, first_s: float, limit: int) -> tuple[list[dict], int]:
        """The waypoint dicts at :meth:`waypoint_offsets`, and how many the lane has in all."""
        s, total = self.waypoint_offsets(first_s, limit)
        return waypoint_dicts([(self, s)]), total

    def _sample(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centreline x, y [m] and heading [rad] at offsets ``s``: :meth:`position_at` and
        :meth:`heading_at` without their np.clip and np.stack wrappers. np.interp already holds
        the end values beyond the lane; the heading is the last segment's at the very end."""
        cum = self.cumulative_s
        if len(self._inner_s):
            at = np.minimum(s, self.length - 1e-9)
            heading = self.segment_headings[self._inner_s.searchsorted(at, side="right")]
        else:  # one segment (a straight lane): one heading
            heading = np.full(len(s), self.segment_headings[0])
        return np.interp(s, cum, self._xs), np.interp(s, cum, self._ys), heading

    @property
    def heading_start(self) -> float:
        return float(self.segment_headings[0])

    @property
    def heading_end(self) -> float:
        return float(self.segment_headings[-1])

    def __repr__(self) -> str:
        return f"Lane({self.id!r}, length={self.length:.1f}, width={self.width:.2f})"


def angle_between(a: float, b: float) -> float:
    """Absolute difference of two headings [rad], in [0, pi]."""
    return abs(math.remainder(a - b, 2 * math.pi))


class WaypointArrays(NamedTuple):
    """Waypoints as flat arrays over all their points, in order: the values of the waypoint
    dicts (before any float32 conversion), sampled per lane in one pass."""

    counts: list[int]  # points of each path, in order (one path: all of them)
    x: np.ndarray  # [m], rounded to 0.1 mm as the dicts' "pos"
    y: np.ndarray
    heading: np.ndarray  # [rad]
    lane_offset: np.ndarray  # [m] along each point's lane
    pieces: list[tuple[Lane, int]]  # the points' lanes in order: (lane, how many points)


def sample_waypoints(pieces: list[tuple[Lane, np.ndarray]], counts: list[int]) -> WaypointArrays:
    """The waypoints at offsets ``s`` along each (lane, s) piece, in order, making up paths of
    ``counts`` points (their sum: every piece's points)."""
    pieces = [(lane, s) for lane, s in pieces if len(s)]
    if not pieces:
        z = np.zeros(0)
        return WaypointArrays(counts, z, z, z, z, [])
    sampled = [lane._sample(s) for lane, s in pieces]
    return WaypointArrays(
        counts,
        np.concatenate([x for x, _, _ in sampled]).round(4),
        np.concatenate([y for _, y, _ in sampled]).round(4),
        np.concatenate([h for _, _, h in sampled]),
        np.concatenate([s for _, s in pieces]),
        [(lane, len(s)) for lane, s in pieces],
    )


def waypoint_dicts(pieces: list[tuple[Lane, np.ndarray]]) -> list[dict]:
    """Waypoint dicts at offsets ``s`` along each (lane, s) piece, in order."""
    return as_dicts(sample_waypoints(pieces, [sum(len(s) for _, s in pieces)]))


def as_dicts(waypoints: WaypointArrays) -> list[dict]:
    """The waypoint dicts of ``waypoints``, all paths' in one list.

    Built afresh for every observation (paths start level with the vehicle), so this is the hot
    path of one: the values are boxed to floats in one pass over all points, as numpy's per-call
    cost outweighs the arithmetic on ~50 points.
    """
    xs, ys = waypoints.x.tolist(), waypoints.y.tolist()
    headings, offsets = waypoints.heading.tolist(), waypoints.lane_offset.tolist()
    # Copies of one template per lane (the key order of the documented waypoint), then the
    # three values per point: faster than a dict display of seven keys.
    out: list[dict] = []
    for lane, count in waypoints.pieces:
        template = {
            "pos": None,
            "heading": None,
            "lane_id": lane.id,
            "lane_index": lane.index,
            "lane_width": lane.width,
            "speed_limit": lane.speed_limit,
            "lane_offset": None,
        }
        out += [template.copy() for _ in range(count)]
    for point, x, y, h, si in zip(out, xs, ys, headings, offsets, strict=True):
        point["pos"] = [x, y]
        point["heading"] = h
        point["lane_offset"] = si
    return out
