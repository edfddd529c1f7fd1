"""Waypoint paths as the protocol carries them, and the one builder of the waypoint dicts.

An observation's waypoint paths are its bulk: about 200 dicts of seven keys for four paths of 50
points (``docs/agent-interface.md``). Building, pickling, freeing and unpickling them cost more
than the rest of a native observation, so the evaluator sends them packed instead: each path's
point count, the constants of each run of points on one lane, and the points' own values in one
buffer. The runtime turns them into the dicts before the policy sees them
(:func:`expand_observations`). The simulator builds an in-process agent's dicts with the same
:func:`waypoint_paths`, so a policy gets the same values in process and in every sandbox, by
construction.

Standard library only: this module runs inside the sandbox (loaded beside ``main.py``).
"""

from __future__ import annotations

from itertools import repeat

# Each point's own values in the buffer, point after point (float64, this machine's byte order:
# the evaluator and the sandbox share the machine).
POINT_VALUES = ("x", "y", "heading", "lane_offset")

# (lane id, lane index, lane width [m], speed limit [m/s], points): a run of points on one lane
LaneRun = tuple[str, int, float, float, int]
# (points of each path, the runs of points on one lane in path order, POINT_VALUES of every point)
PackedPaths = tuple[list[int], list[LaneRun], bytes]


def waypoint_paths(counts: list[int], lanes: list[LaneRun], values: bytes) -> list[list[dict]]:
    """The waypoint dicts of each path of a :data:`PackedPaths`."""
    numbers = memoryview(values).cast("d").tolist()
    total = sum(counts)
    if sum(run[-1] for run in lanes) != total or len(numbers) != len(POINT_VALUES) * total:
        raise ValueError("packed waypoint paths whose counts, lanes and values disagree")
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
    paths, start = [], 0
    for count in counts:
        paths.append(points[start : start + count])
        start += count
    return paths


def expand_observations(observations: object) -> None:
    """Replace, in place, the packed waypoint paths of an act message's observations (agent id
    -> observation dict) by their dicts; dicts already expanded are left as they are."""
    if not isinstance(observations, dict):
        return
    for obs in observations.values():
        if isinstance(obs, dict) and isinstance(obs.get("waypoint_paths"), tuple):
            obs["waypoint_paths"] = waypoint_paths(*obs["waypoint_paths"])
