"""Waypoint paths ahead of a vehicle: one per lane of its road, continuing into successors.

Paths follow the mission route: at a fork the successor that leads onto the route is taken, also
through chains of junction-internal lanes, and inside a junction the path starts on the junction
lane that leads onto the route even when another (overlapping) junction lane is nearer. Points are
:data:`WAYPOINT_SPACING` apart along the lanes, also across lane joins (each lane is entered at
the offset left over from the previous one), so consecutive points never coincide. A path is never
empty: it runs on along successor lanes, stops at a dead end (the end of an acceleration lane or
of the road), and a vehicle past the last regular waypoint of a dead-end lane gets that lane's end
point as its one waypoint.
"""

from __future__ import annotations

import math
from weakref import WeakKeyDictionary

from agent_runtime.packed_waypoints import waypoint_paths as unpacked_paths
from sim.compiled import compiled
from sim.road.centrelines import CentrelineTable, WaypointArrays, packed
from sim.road.lane import WAYPOINT_SPACING, Lane
from sim.road.network import LanePosition, RoadNetwork

_MAX_LANE_HOPS = 256  # a path crosses at most this many lanes (zero-length junction lanes)
_MAX_INTERNAL_CHAIN = 8  # junction-internal lanes in a row before a normal lane
_JUNCTION_MATCH_DISTANCE = 0.5  # [m] a route lane this much farther than the nearest still wins

_sampling = compiled("sim.road._sampling")
_junction_lanes: WeakKeyDictionary[RoadNetwork, dict[str, list[Lane]]] = WeakKeyDictionary()
_predecessor_cache: WeakKeyDictionary[RoadNetwork, dict[str, list[Lane]]] = WeakKeyDictionary()
_successor_cache: WeakKeyDictionary[RoadNetwork, dict[tuple[str, tuple[str, ...]], Lane]] = (
    WeakKeyDictionary()
)
_centrelines: WeakKeyDictionary[RoadNetwork, CentrelineTable] = WeakKeyDictionary()


ROAD_WAYPOINTS_HORIZON = 20  # [m] SMARTS's default RoadWaypoints(horizon=20)


def exit_edge(road: RoadNetwork, lane: Lane) -> str:
    """The normal edge a vehicle reaches from ``lane``: its own edge unless ``lane`` is a
    junction-internal lane, then the edge at the end of its chain of internal lanes."""
    for _ in range(_MAX_INTERNAL_CHAIN):
        if not lane.is_internal or not lane.successors:
            break
        lane = road.lanes[lane.successors[0]]
    return lane.edge_id


def preferred_successor(road: RoadNetwork, lane: Lane, route: tuple[str, ...]) -> Lane | None:
    """The successor of ``lane`` that stays on ``route`` (also through a junction's chain of
    internal lanes), else the first one; None at a dead end."""
    if not lane.successors:
        return None
    # Asked for every path of every observation, with few distinct (lane, route) pairs.
    by_road = _successor_cache.get(road)
    if by_road is None:
        by_road = _successor_cache[road] = {}
    key = (lane.id, tuple(route))
    if key not in by_road:
        by_road[key] = _route_successor(road, lane, route)
    return by_road[key]


def _route_successor(road: RoadNetwork, lane: Lane, route: tuple[str, ...]) -> Lane:
    successors = [road.lanes[succ_id] for succ_id in lane.successors]
    edge = exit_edge(road, lane)
    # Edges after the current one first: a route that passes an edge twice goes on, not back.
    ahead = route[route.index(edge) + 1 :] if edge in route else route
    for edges in (ahead, route):
        for succ in successors:
            if exit_edge(road, succ) in edges:
                return succ
    return successors[0]


def waypoint_paths(
    road: RoadNetwork,
    position: LanePosition,
    x: float,
    y: float,
    route: tuple[str, ...],
    max_paths: int,
    per_path: int,
) -> list[list[dict]]:
    """Up to ``max_paths`` paths of 1 to ``per_path`` waypoints (1 m apart) starting level with
    (x, y) on each lane of the vehicle's road, nearest lanes to the vehicle's own first, then
    ordered by lane index. In a junction, one path along the junction lane that leads onto
    ``route``. Built afresh for each call, from :func:`waypoint_arrays`."""
    starts = path_starts(road, position, x, y, route, max_paths)
    return split_paths(waypoint_arrays(road, starts, route, per_path))


def path_starts(
    road: RoadNetwork,
    position: LanePosition,
    x: float,
    y: float,
    route: tuple[str, ...],
    max_paths: int,
) -> list[tuple[Lane, float]]:
    """The (lane, s) each of :func:`waypoint_paths`'s paths starts from, in their order."""
    here = position.lane
    if here.is_internal:
        return [route_lane_in_junction(road, position, x, y, route)]
    lanes = road.edges[here.edge_id]  # by index
    if len(lanes) > max_paths:
        nearest = sorted(lanes, key=lambda lane: abs(lane.index - here.index))[:max_paths]
        lanes = sorted(nearest, key=lambda lane: lane.index)
    return [(lane, position.s if lane is here else lane.project(x, y)[0]) for lane in lanes]


def waypoint_arrays(
    road: RoadNetwork, starts: list[tuple[Lane, float]], route: tuple[str, ...], n: int
) -> WaypointArrays:
    """The waypoints of paths of up to ``n`` points from each (lane, s) of ``starts``
    (:func:`path_starts`), sampled into arrays in one pass over all paths: what the arrays
    observation holds, and what the waypoint dicts are made from. A path with no point ahead
    holds its last lane's end point."""
    table = _centrelines.get(road)
    if table is None:
        table = _centrelines[road] = CentrelineTable(road.lanes.values())
    if _sampling is not None:
        return table.paths(starts, n, lambda lane: preferred_successor(road, lane, route))
    pieces: list[tuple[Lane, float, int]] = []
    counts = []
    for lane, s in starts:
        walk, last_lane, count = _path_pieces(road, lane, s, route, n)
        if not count:
            walk, count = [(last_lane, last_lane.length, 1)], 1
        pieces += walk
        counts.append(count)
    return table.sample(pieces, counts)


def split_paths(waypoints: WaypointArrays) -> list[list[dict]]:
    """The waypoint dicts of each path of ``waypoints``: those the runtime makes of them in a
    sandbox (:mod:`agent_runtime.packed_waypoints`)."""
    return unpacked_paths(*packed(waypoints))


def road_waypoints(
    road: RoadNetwork,
    position: LanePosition,
    x: float,
    y: float,
    route: tuple[str, ...],
    horizon: int = ROAD_WAYPOINTS_HORIZON,
) -> dict[str, list[list[dict]]]:
    """SMARTS's ``road_waypoints``: for each lane of the vehicle's road (its junction lane in a
    junction), lane id -> one path starting ``horizon`` [m] behind the vehicle's offset on that
    lane (at the lane's start when nearer) and running ``2 * horizon`` waypoints on, 1 m apart,
    along the route."""
    here = position.lane
    lanes = [here] if here.is_internal else road.edges[here.edge_id]
    starts = []
    for lane in lanes:
        s = position.s if lane is here else lane.project(x, y)[0]
        starts.append((lane, max(s - horizon, 0.0)))
    paths = split_paths(waypoint_arrays(road, starts, route, 2 * horizon + 1))
    return {lane.id: [path] for (lane, _), path in zip(starts, paths, strict=True)}


def route_lane_in_junction(
    road: RoadNetwork, position: LanePosition, x: float, y: float, route: tuple[str, ...]
) -> tuple[Lane, float]:
    """The junction lane under (x, y) that leads onto ``route``, and s [m] on it.

    Junction lanes from one incoming lane overlap at first (straight on, left, right); the
    nearest one, which ``position`` holds, need not be the vehicle's way. Among the lanes of the
    same junction within the vehicle's own lane surface that exit onto the route, the one the
    path took before the junction (its entering lane's preferred successor) wins while the
    vehicle is on it, so the path does not jump to a neighbouring turning lane; else the
    nearest."""
    here = position.lane
    if not route or exit_edge(road, here) in route:
        return here, position.s
    candidates: list[tuple[float, Lane, float]] = []
    for lane in _lanes_of_junction(road, here):
        if lane is here or exit_edge(road, lane) not in route:
            continue
        s, _, _ = lane.project(x, y)
        px, py = lane.point_at(s)
        distance = math.hypot(px - x, py - y)
        if distance <= max(position.distance + _JUNCTION_MATCH_DISTANCE, lane.width / 2):
            candidates.append((distance, lane, s))
    if not candidates:
        return here, position.s
    predecessors = _predecessors(road)
    taken = [
        c
        for c in candidates
        if any(preferred_successor(road, p, route) is c[1] for p in predecessors.get(c[1].id, ()))
    ]
    _, lane, s = min(taken or candidates, key=lambda c: c[0])
    return lane, s


def _predecessors(road: RoadNetwork) -> dict[str, list[Lane]]:
    found = _predecessor_cache.get(road)
    if found is None:
        found = {}
        for lane in road.lanes.values():
            for succ_id in lane.successors:
                found.setdefault(succ_id, []).append(lane)
        _predecessor_cache[road] = found
    return found


def _lanes_of_junction(road: RoadNetwork, lane: Lane) -> list[Lane]:
    by_junction = _junction_lanes.get(road)
    if by_junction is None:
        by_junction = {}
        for other in road.lanes.values():
            if other.is_internal:
                by_junction.setdefault(_junction_id(other), []).append(other)
        _junction_lanes[road] = by_junction
    return by_junction.get(_junction_id(lane), [])


def _junction_id(lane: Lane) -> str:
    # SUMO names internal edges ":<junction id>_<index>".
    return lane.edge_id[1:].rsplit("_", 1)[0]


def _path_pieces(
    road: RoadNetwork, lane: Lane, s: float, route: tuple[str, ...], n: int
) -> tuple[list[tuple[Lane, float, int]], Lane, int]:
    """The (lane, first offset, how many) of a path's waypoints on each lane it crosses, the
    first level with s; the lane the path ends on (whose end point is the one waypoint of an
    empty path); and how many points it has."""
    pieces: list[tuple[Lane, float, int]] = []
    count, first_s = 0, s
    for _ in range(_MAX_LANE_HOPS):
        on_lane = lane.waypoint_count(max(first_s, 0.0))
        taken = min(n - count, on_lane)
        pieces.append((lane, max(first_s, 0.0), taken))
        count += taken
        if count >= n:
            break
        # The next point lies past this lane's end by what is left of one spacing.
        first_s = first_s + on_lane * WAYPOINT_SPACING - lane.length
        successor = preferred_successor(road, lane, route)
        if successor is None:
            break
        lane = successor
    return pieces, lane, count


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
