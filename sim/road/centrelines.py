"""Lane centrelines in one set of arrays, so that every waypoint of an observation (all paths, all
the lanes they cross) is sampled by one search and one gather instead of numpy calls per lane.

The values are those of ``np.interp`` over each lane's own polyline, bit for bit: the search
finds the same vertex (the last one at or before the offset: complex keys order by lane, then
offset, so no lane's offsets are shifted), and the interpolation is ``np.interp``'s own
arithmetic, slope times the distance from that vertex plus its value, with its slopes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from agent_runtime.packed_waypoints import POINT_VALUES, PackedPaths
from sim.compiled import compiled
from sim.road.lane import WAYPOINT_SPACING, Lane

_sampling = compiled("sim.road._sampling")

# [m] offsets of a piece's points from its first (a longer piece makes its own: _piece_steps)
_STEPS = WAYPOINT_SPACING * np.arange(256)
# Rows of CentrelineTable.values (a column per centreline vertex of every lane); after the
# gather, rows X .. INDEX hold each waypoint's values (see WaypointArrays.values).
_CUM, _SLOPE_X, _SLOPE_Y, X, Y, HEADING, WIDTH, SPEED_LIMIT, OFFSET, INDEX = range(10)
# A lane's heading at offsets this close to its end is its last segment's (the rule of the
# lanes' own sampling: the next segment would be past the lane).
_END_MARGIN = 1e-9  # [m]
# The rows of WaypointArrays.values a packed path holds for each point, in the protocol's order.
_ROW_OF = {"x": X, "y": Y, "heading": HEADING, "lane_offset": OFFSET}
_PACKED_ROWS = [_ROW_OF[name] - X for name in POINT_VALUES]


class WaypointArrays(NamedTuple):
    """Waypoints as flat arrays over all their points, in order: the values of the waypoint
    dicts (before any float32 conversion)."""

    counts: list[int]  # points of each path, in order (one path: all of them)
    # (7, points): x, y [m] (rounded to 0.1 mm as the dicts' "pos"), heading [rad], lane width
    # [m], speed limit [m/s], offset along the point's lane [m] and lane index; heading to
    # offset in the arrays observation's WAYPOINT_FIELDS order
    values: np.ndarray
    pieces: list[tuple[Lane, int]]  # the points' lanes in order: (lane, how many points)


class CentrelineTable:
    """The centreline vertices of ``lanes``, lane after lane, with what sampling needs at each:
    its offset along its lane, the slopes of x and y on to the next vertex (0 at a lane's last
    one), its position, the lane's heading there and the lane's constants."""

    def __init__(self, lanes: Iterable[Lane]) -> None:
        self.lanes = lanes = list(lanes)
        self.ordinal = {lane: k for k, lane in enumerate(lanes)}  # Lanes hash by identity
        # A column of zeros first: the search counts the vertices at or before an offset, so
        # the count is the column of the vertex found.
        columns, keys = [np.zeros((INDEX + 1, 1))], []
        vertices = []
        for k, lane in enumerate(lanes):
            cum, pts = lane.cumulative_s, lane.centreline
            n = len(cum)
            vertices.append(n)
            values = np.zeros((INDEX + 1, n))
            values[_CUM], values[X], values[Y] = cum, pts[:, 0], pts[:, 1]
            # np.interp's slopes, (y[j+1] - y[j]) / (s[j+1] - s[j]). A zero-length segment's
            # (0 / 0) is never used: the search passes over its first vertex.
            with np.errstate(divide="ignore", invalid="ignore"):
                values[_SLOPE_X : _SLOPE_Y + 1, :-1] = np.diff(pts.T) / np.diff(cum)
            # The segment under a vertex, up to the one the lane's end (less _END_MARGIN) is on.
            last = int(cum[1:-1].searchsorted(lane.length - _END_MARGIN, side="right"))
            values[HEADING] = lane.segment_headings[np.minimum(np.arange(n), last)]
            values[WIDTH], values[SPEED_LIMIT], values[INDEX] = (
                lane.width,
                lane.speed_limit,
                lane.index,
            )
            columns.append(values)
            keys.append(k + 1j * cum)
        self.values = np.concatenate(columns, axis=1)
        self.keys = np.concatenate(keys)  # (lane ordinal, offset), in lexicographic order
        # Each lane's vertices and the column of its first, for the compiled core's search.
        self._vertices = np.array(vertices, dtype=np.int64)
        self._first_column = 1 + np.concatenate([[0], np.cumsum(self._vertices)[:-1]])
        # Where an offset falls on a vertex, np.interp gives the vertex's own value, where the
        # slope's term (+0 or -0) would turn a vertex's -0 into +0: only -0 needs telling.
        xy = self.values[X : Y + 1]
        self._negative_zeros = bool(np.any(np.signbit(xy) & (xy == 0.0)))

    def sample(self, pieces: list[tuple[Lane, float, int]], counts: list[int]) -> WaypointArrays:
        """The waypoints at offsets ``first_s`` + k * :data:`WAYPOINT_SPACING` [m], k = 0 ..
        count - 1, along each (lane, first_s, count) of ``pieces``, in order, making up paths
        of ``counts`` points (their sum: every piece's points). ``first_s`` is at least 0 and
        no offset past the lane's end."""
        pieces = [piece for piece in pieces if piece[2]]
        if not pieces:
            return WaypointArrays(counts, np.zeros((INDEX - X + 1, 0)), [])
        ordinal = self.ordinal
        piece_counts = tuple([count for _, _, count in pieces])
        # Each point's search key: its lane's ordinal, and its offset (the imaginary part).
        key = np.array([complex(ordinal[lane], s) for lane, s, _ in pieces]).repeat(piece_counts)
        key.imag += _piece_steps(piece_counts)
        s = key.imag
        values = self.values.take(self.keys.searchsorted(key, side="right"), axis=1)
        ds = s - values[_CUM]
        xy = values[X : Y + 1]
        if self._negative_zeros:
            np.copyto(xy, values[_SLOPE_X : _SLOPE_Y + 1] * ds + xy, where=ds != 0.0)
        else:
            xy += values[_SLOPE_X : _SLOPE_Y + 1] * ds
        xy.round(4, out=xy)
        values[OFFSET] = s
        return WaypointArrays(counts, values[X:], [(lane, count) for lane, _, count in pieces])

    def paths(
        self,
        starts: list[tuple[Lane, float]],
        n: int,
        successor: Callable[[Lane], Lane | None],
    ) -> WaypointArrays:
        """:func:`sim.road.waypoints.waypoint_arrays` by the compiled core: the paths of up to
        ``n`` points from each (lane, s) of ``starts``, ``successor`` giving the lane after
        each (None at a dead end)."""
        ordinal, lanes = self.ordinal, self.lanes

        def next_ordinal(k: int) -> int:
            lane = successor(lanes[k])
            return -1 if lane is None else ordinal[lane]

        counts, values, pieces = _sampling.paths(
            self.values,
            self._first_column,
            self._vertices,
            [(ordinal[lane], s) for lane, s in starts],
            n,
            next_ordinal,
            self._negative_zeros,
        )
        return WaypointArrays(counts, values, [(lanes[k], count) for k, count in pieces])


@lru_cache(maxsize=1024)
def _piece_steps(counts: tuple[int, ...]) -> np.ndarray:
    """[m] offsets of each point from its piece's first, for pieces of ``counts`` points: the
    same few counts recur at every step of an episode (e.g. (50, 50, 50) for three full paths
    along long lanes), so the array is made once per counts (read-only: shared)."""
    steps = np.concatenate(
        [_STEPS[:n] if n <= len(_STEPS) else WAYPOINT_SPACING * np.arange(n) for n in counts]
    )
    steps.flags.writeable = False
    return steps


def packed(waypoints: WaypointArrays) -> PackedPaths:
    """``waypoints`` as the protocol carries them (:mod:`agent_runtime.packed_waypoints`, which
    also makes the dicts of in-process agents from this)."""
    lanes = [
        (lane.id, lane.index, lane.width, lane.speed_limit, count)
        for lane, count in waypoints.pieces
    ]
    points = waypoints.values[_PACKED_ROWS].T  # point after point
    return list(waypoints.counts), lanes, points.tobytes()
