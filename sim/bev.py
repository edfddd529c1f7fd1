"""Bird's-eye-view rasters of the agent interface: ``top_down_rgb``, ``occupancy_grid_map`` and
``drivable_area_grid_map`` (``docs/agent-interface.md``).

The road (drivable area, lane markings, each mission's route) is rasterised once per scenario
into world-aligned layers at the interface's resolution; each step crops and rotates them into
the ego's frame with one affine warp (cost proportional to the output image, not the map), then
draws the vehicles. Every image is ``(img_pixels, img_pixels)`` (``(..., 3)`` for RGB) uint8,
ego-centred and heading-up: the ego is at the centre pixel facing the top edge (row 0), its left
to the image's left. Nearest-neighbour sampling only, so images are identical across runs.

Only vehicles within the interface's ``observation_radius`` are drawn (those are the ones the
simulator reports around the ego).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon

from sim.geometry import box_corners
from sim.interface import AgentInterface
from sim.road import RoadNetwork
from sim.road.network import lane_surface
from sim.vehicle.states import VehicleStates

RASTER_NAMES = ("drivable_area_grid_map", "occupancy_grid_map", "top_down_rgb")

# RGB colours of top_down_rgb; one per kind of thing so a network can tell them apart.
COLOURS: dict[str, tuple[int, int, int]] = {
    "background": (0, 0, 0),
    "road": (80, 80, 80),
    "route": (40, 70, 140),  # lanes of the ego's own route edges
    "lane_marking": (230, 230, 230),
    "vehicle": (200, 40, 40),  # traffic (SUMO or replayed)
    "mission_agent": (230, 170, 20),  # other mission vehicles
    "ego": (40, 200, 60),
}
OCCUPIED = 255  # value of occupied / drivable cells in the grid maps
_SHIFT = 4  # fixed-point bits for OpenCV polygon vertices (1/16 px precision)
_MAX_LAYER_PIXELS = 80_000_000  # a larger map would need a coarser world layer


@dataclass(frozen=True)
class EgoPose:
    x: float  # [m]
    y: float  # [m]
    heading: float  # [rad], 0 along +x, counter-clockwise
    length: float  # [m]
    width: float  # [m]


class _WorldLayers:
    """North-up world rasters of one road network: pixel (col, row) is the world point
    (x0 + col / res, y1 - row / res)."""

    def __init__(self, road: RoadNetwork, res: float, margin: float) -> None:
        x0, y0, x1, y1 = road.bounds
        self.res, self.x0, self.y1 = res, x0 - margin, y1 + margin
        cols = math.ceil((x1 - x0 + 2 * margin) * res) + 1
        rows = math.ceil((y1 - y0 + 2 * margin) * res) + 1
        if cols * rows > _MAX_LAYER_PIXELS:
            raise ValueError(f"map too large for rasters at {res:.2f} px/m ({cols}x{rows} px)")
        self.shape = (rows, cols)
        self.drivable = np.zeros(self.shape, np.uint8)
        self.fill(self.drivable, road.drivable_area, OCCUPIED)
        self.markings = np.zeros(self.shape, np.uint8)
        for lane in road.lanes.values():
            if not lane.is_internal:
                ring = self.to_px(np.asarray(lane_surface(lane).exterior.coords))
                cv2.polylines(self.markings, [ring], True, OCCUPIED, 1, cv2.LINE_8, _SHIFT)
        self.markings &= self.drivable  # markings only on the road surface

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World points (n, 2) [m] as fixed-point pixel coordinates (n, 2) int32."""
        scale = self.res * (1 << _SHIFT)
        px = np.empty((len(xy), 2))
        px[:, 0] = (xy[:, 0] - self.x0) * scale
        px[:, 1] = (self.y1 - xy[:, 1]) * scale
        return np.round(px).astype(np.int32)

    def fill(self, layer: np.ndarray, geometry, value: int) -> None:
        """Fill a (multi)polygon's exteriors with ``value`` and cut its holes back out."""
        polygons = geometry.geoms if isinstance(geometry, MultiPolygon) else [geometry]
        polygons = [p for p in polygons if isinstance(p, Polygon) and not p.is_empty]
        outer = [self.to_px(np.asarray(p.exterior.coords)) for p in polygons]
        holes = [self.to_px(np.asarray(r.coords)) for p in polygons for r in p.interiors]
        if outer:
            cv2.fillPoly(layer, outer, value, cv2.LINE_8, _SHIFT)
        if holes:
            cv2.fillPoly(layer, holes, 0, cv2.LINE_8, _SHIFT)


class BevRenderer:
    """Renders the rasters an :class:`AgentInterface` asks for. Build once per scenario."""

    def __init__(
        self, road: RoadNetwork, interface: AgentInterface, routes: dict[str, tuple[str, ...]]
    ) -> None:
        self.names = tuple(n for n in RASTER_NAMES if getattr(interface, n))
        self.pixels = interface.img_pixels
        self.res = interface.img_pixels / interface.img_meters  # [px/m]
        self.mission_ids = frozenset(routes)
        if not self.names:
            return
        # OpenCV's worker threads cost more CPU than they save on images this small (one render,
        # 256 px, 2 cores: 0.39-0.66 ms CPU with them, 0.30 ms without), and a machine running
        # simulators already has one busy per core. Process-wide, but only where rasters are drawn.
        cv2.setNumThreads(1)
        # The margin keeps the image's corners inside the layers anywhere on the road.
        self._world = _WorldLayers(road, self.res, interface.img_meters)
        world = self._world
        base = np.zeros((*world.shape, 3), np.uint8)
        base[world.drivable > 0] = COLOURS["road"]
        self._base = base
        self._route_base: dict[str, np.ndarray] = {}
        if "top_down_rgb" in self.names:
            for agent_id, route in routes.items():
                self._route_base[agent_id] = self._with_route(road, route)
            base[world.markings > 0] = COLOURS["lane_marking"]

    def _with_route(self, road: RoadNetwork, route: tuple[str, ...]) -> np.ndarray:
        world = self._world
        mask = np.zeros(world.shape, np.uint8)
        surfaces = [lane_surface(lane) for e in route for lane in road.edges.get(e, ())]
        if surfaces:
            world.fill(mask, shapely.unary_union(surfaces), OCCUPIED)
        layer = self._base.copy()
        layer[(mask > 0) & (world.drivable > 0)] = COLOURS["route"]
        layer[world.markings > 0] = COLOURS["lane_marking"]
        return layer

    def _affine(self, ego: EgoPose) -> np.ndarray:
        """2x3 matrix taking an ego image pixel (col, row) to its world-layer pixel."""
        w, half = self._world, self.pixels / 2
        c, s = math.cos(ego.heading), math.sin(ego.heading)
        # Image pixel -> ego frame: forward = (half - row) / res, left = (half - col) / res.
        # Ego frame -> world: p = ego + forward * (c, s) + left * (-s, c).
        # World -> layer: col = (x - x0) * res, row = (y1 - y) * res.
        # Composed, the two resolutions cancel.
        m = np.array(
            [
                [s, -c, (ego.x - w.x0) * w.res + half * (c - s)],
                [c, s, (w.y1 - ego.y) * w.res - half * (s + c)],
            ]
        )
        return m

    def to_image(self, ego: EgoPose, xy: np.ndarray) -> np.ndarray:
        """World points (n, 2) [m] as image pixel coordinates (n, 2) [px] (col, row)."""
        c, s = math.cos(ego.heading), math.sin(ego.heading)
        rx, ry = xy[:, 0] - ego.x, xy[:, 1] - ego.y
        forward, left = rx * c + ry * s, -rx * s + ry * c
        half = self.pixels / 2
        return np.stack([half - left * self.res, half - forward * self.res], 1)

    def render(self, agent_id: str, ego: EgoPose, others: VehicleStates) -> dict[str, np.ndarray]:
        """The requested rasters of ``agent_id`` at ``ego``; ``others`` are the vehicles around it
        (traffic and other mission agents, told apart by id)."""
        if not self.names:
            return {}
        size = (self.pixels, self.pixels)
        m = self._affine(ego)
        flags = cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP
        out: dict[str, np.ndarray] = {}
        if "drivable_area_grid_map" in self.names:
            out["drivable_area_grid_map"] = cv2.warpAffine(
                self._world.drivable, m, size, flags=flags
            )
        boxes = self._boxes(ego, others)
        if "occupancy_grid_map" in self.names:
            grid = np.zeros(size, np.uint8)
            cv2.fillPoly(grid, [b for b, _ in boxes], OCCUPIED, cv2.LINE_8, _SHIFT)
            out["occupancy_grid_map"] = grid
        if "top_down_rgb" in self.names:
            layer = self._route_base.get(agent_id, self._base)
            rgb = cv2.warpAffine(layer, m, size, flags=flags)
            for box, kind in boxes:
                cv2.fillPoly(rgb, [box], COLOURS[kind], cv2.LINE_8, _SHIFT)
            out["top_down_rgb"] = rgb
        return out

    def _boxes(self, ego: EgoPose, others: VehicleStates) -> list[tuple[np.ndarray, str]]:
        """Fixed-point image polygons of every vehicle and their colour names, ego last."""
        n = len(others)
        x = np.append(others.x, ego.x)
        y = np.append(others.y, ego.y)
        corners = box_corners(
            x,
            y,
            np.append(others.heading, ego.heading),
            np.append(others.length, ego.length),
            np.append(others.width, ego.width),
        )  # (n + 1, 4, 2) [m]
        px = self.to_image(ego, corners.reshape(-1, 2)) * (1 << _SHIFT)
        polys = np.round(px).astype(np.int32).reshape(n + 1, 4, 2)
        kinds = ["mission_agent" if i in self.mission_ids else "vehicle" for i in others.ids]
        return [*zip(polys[:n], kinds, strict=True), (polys[n], "ego")]
