"""One lane of the road network: its centreline as a polyline and the lane-frame maths on it."""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from arena import portable_math
from sim.compiled import compiled

_lane_search = compiled("sim.road._lane_search")

WAYPOINT_SPACING = 1.0  # [m] distance between consecutive waypoints along a lane
# Lanes of more centreline points than this are projected onto through a grid of their segments
# (numpy over all segments when the grid cannot tell), fewer with a scalar loop over all; every
# way gives the same result.
_VECTOR_PROJECTION_POINTS = 16
_CELL = 4.0  # [m] side of a long lane's grid cell
_CELL_REACH_D2 = 3.0**2  # [m^2] a nearest segment this near is certainly listed in the cell


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
    _shape = None  # the compiled core's copy of the centreline (_make_shape), when it runs

    def __post_init__(self) -> None:
        pts = np.asarray(self.centreline, dtype=np.float64)
        if len(pts) < 2 or np.allclose(pts[0], pts[-1]):
            # Zero-length internal lanes exist; give them a tiny extent so the maths stays finite.
            pts = np.array([pts[0], pts[0] + [1e-3, 0.0]])
        self.centreline = pts
        seg = np.diff(pts, axis=0)
        self.segment_lengths = np.hypot(seg[:, 0], seg[:, 1])  # (n-1,) [m]
        self.segment_headings = portable_math.arctan2(seg[:, 1], seg[:, 0])  # (n-1,) [rad]
        self.cumulative_s = np.concatenate([[0.0], np.cumsum(self.segment_lengths)])  # (n,) [m]
        self.length = float(self.cumulative_s[-1])  # [m]
        self._points = pts.tolist()
        # What _frame reads per projection, as plain floats (the same values, without numpy
        # scalar indexing; lengths by math.hypot, as _frame measured them).
        self._cum_list = self.cumulative_s.tolist()
        self._heading_list = self.segment_headings.tolist()
        self._frame_len = [
            max(math.hypot(x1 - x0, y1 - y0), 1e-12)
            for (x0, y0), (x1, y1) in pairwise(self._points)
        ]
        self._seg_len2 = np.maximum(seg[:, 0] * seg[:, 0] + seg[:, 1] * seg[:, 1], 1e-12)
        self._len2_list = self._seg_len2.tolist()
        self._cells: dict[tuple[int, int], list[int]] | None = None  # long lanes: _make_cells

    def project(self, x: float, y: float) -> tuple[float, float, float]:
        """Lane coordinates of a point: (s [m] along the lane, t [m] signed lateral offset, left
        positive, heading [rad] of the lane at s), on the lane's first nearest segment."""
        if _lane_search is not None:
            return (self._shape or self._make_shape()).project(x, y)
        pts = self._points
        if len(pts) > _VECTOR_PROJECTION_POINTS:
            return self._project_long(x, y)
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

    def _project_long(self, x: float, y: float) -> tuple[float, float, float]:
        """:meth:`project` onto a lane of many points (curves). The point's cell of the lane's
        grid lists every segment passing within 3 m of it, in index order: a nearest one nearer
        than that is the first nearest of all (:meth:`_project_vectorised`'s arithmetic, on
        floats). Else all segments at once.

        Not :meth:`project`'s loop: that one squares with ``**`` (libm's pow, which differs from
        ``x * x`` in the last bit about once in a thousand) and keeps doing so, so that short
        lanes answer as they always did; this one must multiply, as the numpy search does."""
        cells = self._cells or self._make_cells()
        listed = cells.get((math.floor(x / _CELL), math.floor(y / _CELL)), ())
        pts = self._points
        best = (math.inf, 0, 0.0)
        for i in listed:
            (x0, y0), (x1, y1) = pts[i], pts[i + 1]
            dx, dy = x1 - x0, y1 - y0
            rx, ry = x - x0, y - y0
            u = min(max((rx * dx + ry * dy) / self._len2_list[i], 0.0), 1.0)
            ex, ey = rx - dx * u, ry - dy * u
            d2 = ex * ex + ey * ey
            if d2 < best[0]:
                best = (d2, i, u)
        if best[0] < _CELL_REACH_D2:
            return self._frame(best[1], best[2], x, y)
        return self._project_vectorised(x, y)

    def _project_vectorised(self, x: float, y: float) -> tuple[float, float, float]:
        """:meth:`project` for lanes of many points (curves): the same arithmetic per segment,
        and the first nearest segment wins as in the scalar loop."""
        p0, d = self.centreline[:-1], np.diff(self.centreline, axis=0)
        rx, ry = x - p0[:, 0], y - p0[:, 1]
        u = np.minimum(np.maximum((rx * d[:, 0] + ry * d[:, 1]) / self._seg_len2, 0.0), 1.0)
        ex, ey = rx - d[:, 0] * u, ry - d[:, 1] * u
        i = int(np.argmin(ex * ex + ey * ey))
        return self._frame(i, float(u[i]), x, y)

    def _make_cells(self) -> dict[tuple[int, int], list[int]]:
        """Grid cells of _CELL [m] -> indices of the segments passing within a little more than
        3 m of the cell, ascending (made when a long lane is first projected onto)."""
        cells: dict[tuple[int, int], list[int]] = {}
        reach = math.sqrt(_CELL_REACH_D2) + 1e-3  # listed a little wider than trusted
        for i, ((x0, y0), (x1, y1)) in enumerate(pairwise(self._points)):
            for ix in range(math.floor((min(x0, x1) - reach) / _CELL),
                            math.floor((max(x0, x1) + reach) / _CELL) + 1):  # fmt: skip
                for iy in range(math.floor((min(y0, y1) - reach) / _CELL),
                                math.floor((max(y0, y1) + reach) / _CELL) + 1):  # fmt: skip
                    cells.setdefault((ix, iy), []).append(i)
        self._cells = cells
        return cells

    def _make_shape(self):
        """The compiled core's LaneShape of this lane (its grid too, for a long lane)."""
        long = len(self._points) > _VECTOR_PROJECTION_POINTS
        self._shape = _lane_search.LaneShape(
            np.ascontiguousarray(self.centreline),
            self._seg_len2,
            np.array(self._frame_len),
            self.cumulative_s,
            self.segment_headings,
            (self._cells or self._make_cells()) if long else None,
        )
        return self._shape

    def __getstate__(self) -> dict:
        # The compiled core's shape is not picklable: remade where first needed.
        return {k: v for k, v in self.__dict__.items() if k != "_shape"}

    def _frame(self, i: int, u: float, x: float, y: float) -> tuple[float, float, float]:
        (x0, y0), (x1, y1) = self._points[i], self._points[i + 1]
        seg_len = self._frame_len[i]
        t = ((x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)) / seg_len
        s = self._cum_list[i] + u * seg_len
        return s, t, self._heading_list[i]

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
        """:meth:`position_at` of one offset, as floats. A controller and the junction match ask
        for single points every step, so this is np.interp's arithmetic on Python floats: the
        segment under s found by bisection, a vertex's own value on a vertex, else the slope
        times the distance from the segment's start, plus its start value."""
        s = min(max(float(s), 0.0), self.length)
        cum, points = self._cum_list, self._points
        j = bisect_right(cum, s) - 1
        if j == len(cum) - 1 or cum[j] == s:
            x, y = points[j]
            return x, y
        (x0, y0), (x1, y1) = points[j], points[j + 1]
        ds, run = s - cum[j], cum[j + 1] - cum[j]
        return (x1 - x0) / run * ds + x0, (y1 - y0) / run * ds + y0

    def heading_at(self, s: float | np.ndarray) -> float | np.ndarray:
        """Lane direction [rad] at distance ``s`` [m] along the lane."""
        i = np.clip(
            np.searchsorted(self.cumulative_s, s, side="right") - 1,
            0,
            len(self.segment_headings) - 1,
        )
        return self.segment_headings[i]

    def waypoint_count(self, first_s: float) -> int:
        """How many offsets s = ``first_s`` + k * :data:`WAYPOINT_SPACING` [m], k >= 0, the lane
        has short of its end (``first_s`` at least 0).

        A path starts level with the vehicle (``first_s`` is its own s) and one crossing into
        this lane starts at the offset left over from the previous one, so the spacing stays
        even along the whole path.
        """
        return max(math.ceil((self.length - first_s) / WAYPOINT_SPACING - 1e-9), 0)

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
