"""Waypoint paths ahead of a vehicle: one per lane of its road, continuing into successors."""

from __future__ import annotations

import math

from sim.road.lane import WAYPOINT_SPACING, Lane
from sim.road.network import LanePosition, RoadNetwork


def preferred_successor(road: RoadNetwork, lane: Lane, route: tuple[str, ...]) -> Lane | None:
    """The successor of ``lane`` that stays on ``route`` (also through a junction's internal
    lane), else the first one; None at a dead end."""
    if not lane.successors:
        return None
    for succ_id in lane.successors:
        succ = road.lanes[succ_id]
        if succ.edge_id in route:
            return succ
        if succ.is_internal and any(road.lanes[n].edge_id in route for n in succ.successors):
            return succ
    return road.lanes[lane.successors[0]]


def waypoint_paths(
    road: RoadNetwork,
    position: LanePosition,
    x: float,
    y: float,
    route: tuple[str, ...],
    max_paths: int,
    per_path: int,
) -> list[list[dict]]:
    """Up to ``max_paths`` paths of up to ``per_path`` waypoints (1 m apart) starting level with
    (x, y) on each lane of the vehicle's road, nearest lanes to the vehicle's own first, then
    ordered by lane index. Waypoint dicts are shared between observations (read-only)."""
    here = position.lane
    lanes = road.edges[here.edge_id] if not here.is_internal else [here]
    lanes = sorted(lanes, key=lambda lane: abs(lane.index - here.index))[:max_paths]
    paths = []
    for lane in sorted(lanes, key=lambda lane: lane.index):
        s = position.s if lane is here else lane.project(x, y)[0]
        paths.append(_path_from(road, lane, s, route, per_path))
    return paths


def _path_from(road: RoadNetwork, lane: Lane, s: float, route: tuple[str, ...], n: int) -> list:
    path: list[dict] = []
    start = math.ceil(s / WAYPOINT_SPACING - 1e-9)
    while lane is not None and len(path) < n:
        path.extend(lane.waypoints[start : start + n - len(path)])
        lane = preferred_successor(road, lane, route)
        start = 0
    return path


def route_ahead(road: RoadNetwork, x: float, y: float, heading: float) -> list[str]:
    """Edge ids from the lane at (x, y) onwards, following preferred successors until a dead end
    or a loop: a route for a vehicle that SUMO will drive from there."""
    lane: Lane | None = road.nearest_lane(x, y, heading).lane
    edges: list[str] = []
    while lane is not None and len(edges) < 64:
        if not lane.is_internal:
            if lane.edge_id in edges:
                break
            edges.append(lane.edge_id)
        lane = preferred_successor(road, lane, ())
    return edges
