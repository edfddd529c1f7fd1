"""SMARTS's basic lidar (``lidar_point_cloud`` of the agent interface): 300 horizontal rays of
20 m around the ego, each ending at the first vehicle side or road edge it meets.

Our world is flat, so every ray lies in the plane z = 0 (SMARTS's also sweep no elevation: one
laser angle). Ray k points at the ego's heading + k * 2 pi / 300 (counter-clockwise from straight
ahead). SMARTS adds Gaussian noise (sigma 0.078 m) to each distance; ours is exact, so an episode
replays identically. Road edges are the boundary of the road network's drivable area, split into
segments once per map and found near the ego through an STR tree.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from arena import portable_math
from sim.geometry import box_corners
from sim.road import RoadNetwork
from sim.vehicle.states import VehicleStates

RAYS = 300
RANGE = 20.0  # [m]
_ANGLES = np.arange(RAYS) * (2 * math.pi / RAYS)  # (RAYS,) [rad] from the ego's heading


class Lidar:
    """Casts the rays of one road network. Build once per scenario."""

    def __init__(self, road: RoadNetwork) -> None:
        segments = []
        boundary = road.drivable_area.boundary
        for line in getattr(boundary, "geoms", [boundary]):
            coords = np.asarray(line.coords)
            if len(coords) >= 2:
                segments.append(np.stack([coords[:-1], coords[1:]], 1))
        self._edges = np.concatenate(segments) if segments else np.zeros((0, 2, 2))
        self._tree = shapely.STRtree(shapely.linestrings(self._edges))

    def scan(self, x: float, y: float, heading: float, others: VehicleStates) -> dict:
        """The point cloud at the ego pose (x, y [m], heading [rad], ours: 0 = +x): ``points``
        (RAYS, 3) [m] (inf where the ray met nothing), ``hits`` (RAYS,) bool, ``origins`` and
        ``ends`` (RAYS, 3) [m] of every ray."""
        near = self._tree.query(shapely.box(x - RANGE, y - RANGE, x + RANGE, y + RANGE))
        segments = [self._edges[near]]
        if len(others):
            corners = box_corners(others.x, others.y, others.heading, others.length, others.width)
            sides = np.stack([corners, np.roll(corners, -1, axis=1)], 2)  # (n, 4, 2, 2)
            segments.append(sides.reshape(-1, 2, 2))
        edges = np.concatenate(segments)  # (m, 2, 2) [m]
        angles = heading + _ANGLES
        d = np.stack([portable_math.cos(angles), portable_math.sin(angles)], 1)  # (RAYS, 2)
        distance = np.full(RAYS, np.inf)
        if len(edges):
            p = edges[:, 0] - (x, y)  # (m, 2) segment starts from the origin
            e = edges[:, 1] - edges[:, 0]  # (m, 2)
            denominator = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (p[None, :, 0] * e[None, :, 1] - p[None, :, 1] * e[None, :, 0]) / denominator
                u = (p[None, :, 0] * d[:, None, 1] - p[None, :, 1] * d[:, None, 0]) / denominator
            valid = (denominator != 0) & (t >= 0) & (t <= RANGE) & (u >= 0) & (u <= 1)
            distance = np.where(valid, t, np.inf).min(1)
        hits = np.isfinite(distance)
        origins = np.zeros((RAYS, 3))
        origins[:, 0], origins[:, 1] = x, y
        ends = origins.copy()
        ends[:, :2] += d * RANGE
        points = np.full((RAYS, 3), np.inf)
        points[hits, :2] = origins[hits, :2] + d[hits] * distance[hits, None]
        points[hits, 2] = 0.0
        return {"points": points, "hits": hits, "origins": origins, "ends": ends}
