"""Recorded poses against a built map: which lane a vehicle drives on, and the route it took.

A pose *fits* a lane when its centre is within the lane's half width plus :data:`REACH_M` of the
lane centre line and its heading within :data:`MAX_ANGLE_RAD` of the lane direction there. Inside
junction areas lanes cross and overlap, so every lane near the pose is tried, not only the
nearest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import sumolib

from sim.road.lane import Lane, angle_between
from sim.road.network import RoadNetwork
from sim.trajectories import Trajectory

REACH_M = 0.5  # [m] beyond the lane's half width (NGSIM positions are noisy by about this)
MAX_ANGLE_RAD = math.radians(45.0)


@dataclass(frozen=True)
class Fit:
    lane: Lane | None  # None: no lane fits the pose
    excess_m: float  # [m] distance beyond the half width of the lane (<= 0: inside it)
    angle_rad: float  # [rad] between the pose heading and the lane direction


def fit_pose(road: RoadNetwork, x: float, y: float, heading: float) -> Fit:
    near = road.nearest_lane(x, y, heading)
    angle = angle_between(heading, near.heading)
    excess = near.distance - near.lane.width / 2
    if excess <= REACH_M and angle <= MAX_ANGLE_RAD:
        return Fit(near.lane, excess, angle)
    best = None
    for lane in road.lanes.values():
        s, t, lane_heading = lane.project(x, y)
        lane_excess = abs(t) - lane.width / 2
        if lane_excess > REACH_M or not -REACH_M <= s <= lane.length + REACH_M:
            continue
        lane_angle = angle_between(heading, lane_heading)
        if lane_angle <= MAX_ANGLE_RAD and (best is None or lane_angle < best.angle_rad):
            best = Fit(lane, lane_excess, lane_angle)
    return best or Fit(None, excess, angle)


def fit_trajectory(road: RoadNetwork, tr: Trajectory) -> list[Fit]:
    return [fit_pose(road, x, y, h) for x, y, h in zip(tr.x, tr.y, tr.heading, strict=True)]


def driven_route(net: sumolib.net.Net, fits: list[Fit]) -> tuple[str, ...] | None:
    """The connected SUMO route (edge ids) through every edge the fitted lanes belong to, in the
    order driven; ``None`` if a pose fits no lane or the edges are not connected in the map."""
    if any(f.lane is None for f in fits):
        return None
    edges: list[str] = []
    for f in fits:
        assert f.lane is not None
        if not f.lane.is_internal and (not edges or edges[-1] != f.lane.edge_id):
            edges.append(f.lane.edge_id)
    if not edges:
        return None
    route = [edges[0]]
    for nxt in edges[1:]:
        if nxt in route:  # a wobble back onto an edge already driven
            continue
        path, _ = net.getShortestPath(net.getEdge(route[-1]), net.getEdge(nxt))
        if path is None:
            return None
        route += [e.getID() for e in path[1:]]
    return tuple(route)
