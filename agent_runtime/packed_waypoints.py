"""Waypoint paths as the protocol carries them, and the one builder of the waypoint dicts.

An observation's waypoint paths are its bulk: about 200 dicts of seven keys for four paths of 50
points (``docs/agent-interface.md``). Building, pickling, freeing and unpickling them cost more
than the rest of a native observation, so the evaluator sends them packed instead: each path's
point count, the constants of each run of points on one lane, and the points' own values in one
buffer. The runtime turns them into the dicts before the policy sees them
(:func:`expand_observations`). The simulator builds an in-process agent's dicts with the same
:func:`waypoint_paths`, so a policy gets the same values in process and in every sandbox, by
construction. In a sandbox each path is a :class:`WaypointPath`: a list that makes a waypoint's
dict when the policy first reads it, so that a policy reading a few points of each path (the
keep-lane example reads the first) does not pay for two hundred.

Standard library only: this module runs inside the sandbox (loaded beside ``main.py``).
"""

from __future__ import annotations

from bisect import bisect_right
from itertools import accumulate, repeat

# Each point's own values in the buffer, point after point (float64, this machine's byte order:
# the evaluator and the sandbox share the machine).
POINT_VALUES = ("x", "y", "heading", "lane_offset")

# (lane id, lane index, lane width [m], speed limit [m/s], points): a run of points on one lane
LaneRun = tuple[str, int, float, float, int]
# (points of each path, the runs of points on one lane in path order, POINT_VALUES of every point)
PackedPaths = tuple[list[int], list[LaneRun], bytes]


def _check(counts: list[int], lanes: list[LaneRun], values: memoryview) -> None:
    total = sum(counts)
    if sum(run[-1] for run in lanes) != total or len(values) != len(POINT_VALUES) * total:
        raise ValueError("packed waypoint paths whose counts, lanes and values disagree")


def waypoint_paths(counts: list[int], lanes: list[LaneRun], values: bytes) -> list[list[dict]]:
    """The waypoint dicts of each path of a :data:`PackedPaths`."""
    numbers = memoryview(values).cast("d")
    _check(counts, lanes, numbers)
    points = _points(lanes, numbers)
    paths, start = [], 0
    for count in counts:
        paths.append(points[start : start + count])
        start += count
    return paths


def _points(lanes: list[LaneRun], values: memoryview) -> list[dict]:
    """Every point's dict, of all the paths in turn."""
    numbers = values.tolist()
    points: list[dict] = []
    for lane_id, lane_index, width, speed_limit, count in lanes:
        # Copies of one template per lane (the documented key order), made by map in C: faster
        # than a dict display of seven keys per point.
        template = {
            "pos": None,
            "heading": None,
            "lane_id": lane_id,
            "lane_index": lane_index,
            "lane_width": width,
            "speed_limit": speed_limit,
            "lane_offset": None,
        }
        points += map(dict.copy, repeat(template, count))
    values_of = iter(numbers)  # zip takes a point's four values from it in turn
    quads = zip(points, values_of, values_of, values_of, values_of, strict=True)
    for point, x, y, heading, offset in quads:
        point["pos"] = [x, y]
        point["heading"] = heading
        point["lane_offset"] = offset
    return points


class _Packed:
    """One observation's packed paths, read point by point."""

    __slots__ = ("all", "ends", "lanes", "values")

    def __init__(self, lanes: list[LaneRun], values: memoryview) -> None:
        self.lanes = lanes
        self.ends = list(accumulate(run[-1] for run in lanes))  # points up to each run's end
        self.values = values
        self.all: list[dict] | None = None

    def every_point(self) -> list[dict]:
        """Every point's dict, made for all the paths at once when a first path is read whole
        (the way that makes many dicts fastest)."""
        if self.all is None:
            self.all = _points(self.lanes, self.values)
        return self.all

    def point(self, k: int) -> dict:
        """The dict of point ``k`` (of all the paths'), as :func:`waypoint_paths` makes it."""
        lane_id, lane_index, width, speed_limit, _ = self.lanes[bisect_right(self.ends, k)]
        x, y, heading, offset = self.values[4 * k : 4 * k + 4].tolist()
        return {
            "pos": [x, y],
            "heading": heading,
            "lane_id": lane_id,
            "lane_index": lane_index,
            "lane_width": width,
            "speed_limit": speed_limit,
            "lane_offset": offset,
        }


class WaypointPath(list):
    """A path's waypoint dicts, each made when first read by index; whatever else reads the
    path (iteration, slices, ``==``, ``json``, ``copy``, ``pickle``, ``repr``, changes) makes
    them all first and then is the list's own. It copies and pickles as a plain list."""

    __slots__ = ("_count", "_made", "_packed", "_start")

    def __init__(self, packed: _Packed, start: int, count: int) -> None:
        super().__init__()
        self._packed: _Packed | None = packed
        self._start, self._count = start, count
        self._made: dict[int, dict] = {}

    def _fill(self) -> WaypointPath:
        packed = self._packed
        if packed is not None:
            self._packed = None
            made, start = self._made, self._start
            points = packed.every_point()[start : start + self._count]
            for i, point in made.items():  # the dicts the policy already holds
                points[i] = point
            list.extend(self, points)
            self._made = {}
        return self

    def __len__(self) -> int:
        return self._count if self._packed is not None else list.__len__(self)

    def __getitem__(self, index):
        packed = self._packed
        if packed is None or not isinstance(index, int):
            return list.__getitem__(self._fill(), index)
        i = index + self._count if index < 0 else index
        if not 0 <= i < self._count:
            raise IndexError("list index out of range")
        point = self._made.get(i)
        if point is None:
            point = self._made[i] = packed.point(self._start + i)
        return point

    def unread(self) -> tuple[memoryview, list[LaneRun]] | None:
        """While no dict of the path was made: its points' POINT_VALUES (float64) and its runs of
        points on one lane (``points`` counted in this path), for a reader that wants them in
        bulk (the SMARTS adapter); else None (read the dicts)."""
        packed = self._packed
        if packed is None or self._made:
            return None
        start, end = self._start, self._start + self._count
        runs, run_start = [], 0
        for run, run_end in zip(packed.lanes, packed.ends, strict=True):
            points = min(run_end, end) - max(run_start, start)
            if points > 0:
                runs.append((*run[:-1], points))
            run_start = run_end
        return packed.values[4 * start : 4 * end], runs

    def __reduce__(self) -> tuple:
        return list, (list(self._fill()),)

    def __reduce_ex__(self, protocol: int) -> tuple:
        return self.__reduce__()

    def __radd__(self, other: object):  # before list.__add__ reads an unfilled path's storage
        return other + list(self._fill()) if isinstance(other, list) else NotImplemented


def _filling(name: str):
    method = getattr(list, name)

    def filled(self, *args):
        # another WaypointPath among the arguments is read as a list too (``==``, ``+``)
        return method(self._fill(), *(a._fill() if type(a) is WaypointPath else a for a in args))

    filled.__name__ = name
    return filled


for _name in (
    *("__iter__", "__reversed__", "__contains__", "__repr__", "__sizeof__"),
    *("__eq__", "__ne__", "__lt__", "__le__", "__gt__", "__ge__"),
    *("__add__", "__mul__", "__rmul__", "__iadd__", "__imul__", "__setitem__", "__delitem__"),
    *("append", "extend", "insert", "pop", "remove", "clear", "copy", "count", "index"),
    *("reverse", "sort"),
):
    setattr(WaypointPath, _name, _filling(_name))


def lazy_waypoint_paths(
    counts: list[int], lanes: list[LaneRun], values: bytes
) -> list[WaypointPath]:
    """:func:`waypoint_paths` as :class:`WaypointPath` lists: the same dicts, each made when
    first read."""
    numbers = memoryview(values).cast("d")
    _check(counts, lanes, numbers)
    packed = _Packed(lanes, numbers)
    starts = list(accumulate(counts, initial=0))[:-1]
    return [WaypointPath(packed, start, n) for start, n in zip(starts, counts, strict=True)]


def expand_observations(observations: object) -> None:
    """Replace, in place, the packed waypoint paths of an act message's observations (agent id
    -> observation dict) by their :class:`WaypointPath` lists; dicts already expanded are left
    as they are."""
    if not isinstance(observations, dict):
        return
    for obs in observations.values():
        if isinstance(obs, dict) and isinstance(obs.get("waypoint_paths"), tuple):
            obs["waypoint_paths"] = lazy_waypoint_paths(*obs["waypoint_paths"])
