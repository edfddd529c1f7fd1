"""The road network of a scenario: lanes, junctions and the drivable area, with fast nearest-lane
queries. Read from a SUMO ``.net.xml`` with sumolib; geometry with shapely and numpy."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import GeometryCollection, LineString, MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry

from arena import portable_math
from sim.compiled import compiled
from sim.road.lane import Lane, angle_between

_lane_search = compiled("sim.road._lane_search")

# Lanes whose centreline is within this much of the nearest one [m] compete on heading, so that
# overlapping junction connections resolve to the one the vehicle follows.
_TIE_DISTANCE = 0.5
_GRID_CELL = 5.0  # [m] side of a nearest-lane index cell
_GRID_REACH = 4.0  # [m] segments this close to a cell are listed in it
# nearest_lanes answers batches at least this large from the grid, smaller ones from the tree
# (per call, the grid's numpy costs more than the tree's queries of a few points).
_GRID_BATCH = 256
# [m] a lane nearer than all others by more than this is the nearest however either of two
# computations rounds (their distances differ by far less)
_GRID_MARGIN = 1e-6
_MAX_SEGMENT = 5.0  # [m] longer centreline segments are split in the index
_SURFACE_MARGIN = 0.05  # [m] see _well_inside
_CLEARANCE_MARGIN = 1e-6  # [m] beyond rounding of the distances in in_junction


@dataclass(frozen=True)
class LanePosition:
    """Where a point is in lane coordinates."""

    lane: Lane
    s: float  # [m] along the lane
    t: float  # [m] signed offset from the centreline, left positive
    heading: float  # [rad] lane direction at s
    distance: float  # [m] from the centreline (|t| unless past a lane end)
    # The nearest-lane index segment measured on (RoadNetwork's own per-segment constants).
    segment: int = field(default=-1, compare=False, repr=False)


class RoadNetwork:
    """Lanes (``lanes``: id -> :class:`Lane`), junction areas (``junction_polygons``: valid simple
    polygons only, whatever shapes the network file holds) and the
    drivable area (union of every lane surface and junction area) of a SUMO network.

    Build with :meth:`load`. Queries: :meth:`nearest_lane` (one point, heading-aware),
    :meth:`nearest_lanes` (many points, vectorised), :meth:`is_on_road`, :meth:`in_junction`.
    """

    def __init__(self, lanes: dict[str, Lane], junction_polygons: list[BaseGeometry]) -> None:
        self.lanes = lanes
        # Every consumer (drawing, rasters, in_junction) may rely on plain polygons.
        self.junction_polygons = [
            part
            for area in junction_polygons
            for part in polygon_parts(shapely.make_valid(area))
            # A degenerate outline (a dead end's is a line) has no area to drive on; an invalid
            # one (a bow tie) has an area only once repaired.
            if part.area > 1e-6
        ]
        self.edges: dict[str, list[Lane]] = {}
        for lane in lanes.values():
            self.edges.setdefault(lane.edge_id, []).append(lane)
        for edge_lanes in self.edges.values():
            edge_lanes.sort(key=lambda lane: lane.index)
        self._lane_list = list(lanes.values())
        self._build_segment_index()
        self.drivable_area: BaseGeometry = shapely.unary_union(
            [lane_surface(lane) for lane in self._lane_list] + self.junction_polygons
        )
        shapely.prepare(self.drivable_area)
        self._junction_area = (
            shapely.unary_union(self.junction_polygons) if self.junction_polygons else None
        )
        # Each index segment's distance [m] from every junction area (in_junction's shortcut),
        # measured for all at once: one at a time, when first driven on, cost an episode ~4 ms.
        self._seg_clearance: list[float] = []
        if self._junction_area is not None:
            shapely.prepare(self._junction_area)
            pieces = np.stack([self._seg_p0, self._seg_p0 + self._seg_d], axis=1)
            self._seg_clearance = shapely.distance(
                self._junction_area, shapely.linestrings(pieces)
            ).tolist()

    # Pickled: an episode's process gets the network parsed by its evaluator (sim.inputs).
    def __getstate__(self) -> dict:
        # The segment tree is rebuilt from its arrays: several times faster than unpickling it
        # one geometry at a time; the compiled core's table is remade where first needed.
        return {k: v for k, v in self.__dict__.items() if k not in ("_tree", "_seg_table")}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._seg_table = None
        self._tree = _segment_tree(self._seg_p0, self._seg_d)
        # Geometries are pickled unprepared; the per-step point queries rely on preparation.
        shapely.prepare(self.drivable_area)
        if self._junction_area is not None:
            shapely.prepare(self._junction_area)

    @classmethod
    def load(cls, net_path: Path) -> RoadNetwork:
        import sumolib  # heavy; only when a network is read

        net = sumolib.net.readNet(str(net_path), withInternal=True)
        lanes: dict[str, Lane] = {}
        for edge in net.getEdges(withInternal=True):
            internal = edge.getFunction() == "internal"
            for lane in edge.getLanes():
                lanes[lane.getID()] = Lane(
                    id=lane.getID(),
                    edge_id=edge.getID(),
                    index=lane.getIndex(),
                    centreline=np.asarray(lane.getShape(), dtype=np.float64)[:, :2],
                    width=float(lane.getWidth()),
                    speed_limit=float(lane.getSpeed()),
                    is_internal=internal,
                    is_shoulder=not lane.allows("passenger"),
                    successors=_successors(lane),
                )
        junctions = [
            Polygon(node.getShape()) for node in net.getNodes() if len(node.getShape()) >= 3
        ]
        return cls(lanes, junctions)

    def _build_segment_index(self) -> None:
        p0, p1, lane_idx, s0 = [], [], [], []
        for k, lane in enumerate(self._lane_list):
            # Long segments are split so that each one touches few grid cells.
            pts, cum = _split_long_segments(lane.centreline, lane.cumulative_s)
            p0.append(pts[:-1])
            p1.append(pts[1:])
            lane_idx.append(np.full(len(pts) - 1, k))
            s0.append(cum[:-1])
        self._seg_p0 = np.concatenate(p0)  # (S, 2) [m]
        self._seg_d = np.concatenate(p1) - self._seg_p0  # (S, 2) [m]
        self._seg_len2 = np.maximum((self._seg_d**2).sum(1), 1e-12)  # (S,) [m^2]
        self._seg_len = np.sqrt(self._seg_len2)  # (S,) [m]
        self._seg_lane = np.concatenate(lane_idx)  # (S,)
        self._seg_s0 = np.concatenate(s0)  # (S,) [m]
        self._seg_heading = portable_math.arctan2(
            self._seg_d[:, 1], self._seg_d[:, 0]
        )  # (S,) [rad]
        ends = self._seg_p0 + self._seg_d
        self._tree = _segment_tree(self._seg_p0, self._seg_d)
        # Uniform grid: each cell lists the segments passing within _GRID_REACH of it, so a point
        # whose nearest centreline is closer than that is answered from its own cell.
        lo = np.floor((np.minimum(self._seg_p0, ends) - _GRID_REACH) / _GRID_CELL).astype(int)
        hi = np.floor((np.maximum(self._seg_p0, ends) + _GRID_REACH) / _GRID_CELL).astype(int)
        cells: dict[tuple[int, int], list[int]] = {}
        for k in range(len(lo)):
            for ix in range(lo[k, 0], hi[k, 0] + 1):
                for iy in range(lo[k, 1], hi[k, 1] + 1):
                    cells.setdefault((ix, iy), []).append(k)
        # Plain Python floats: per-point queries do scalar arithmetic on them, which is several
        # times faster than on numpy scalars and gives the same IEEE results.
        rows = list(
            zip(
                range(len(lo)),
                *self._seg_p0.T.tolist(),
                *self._seg_d.T.tolist(),
                self._seg_len2.tolist(),
                self._seg_len.tolist(),
                strict=True,
            )
        )
        self._seg_rows = rows
        self._seg_lane_list = self._seg_lane.tolist()
        self._seg_s0_list = self._seg_s0.tolist()
        self._seg_heading_list = self._seg_heading.tolist()
        self._grid = {cell: [rows[k] for k in segs] for cell, segs in cells.items()}
        self._grid_segments: dict[tuple[int, int], np.ndarray] = {}  # made by nearest_lanes
        self._seg_table: np.ndarray | None = None  # the compiled core's (_make_seg_table)

    def nearest_lane(self, x: float, y: float, heading: float | None = None) -> LanePosition:
        """The lane whose centreline is nearest to (x, y) [m]. Among lanes within 0.5 m of the
        nearest, the one best aligned with ``heading`` [rad] wins (overlapping junction lanes)."""
        if _lane_search is not None:
            listed = (self._grid_segments or self._make_grid_segments()).get(
                (math.floor(x / _GRID_CELL), math.floor(y / _GRID_CELL))
            )
            if listed is not None:
                table = self._seg_table if self._seg_table is not None else self._make_seg_table()
                found = _lane_search.grid_nearest(
                    table, self._seg_lane, self._seg_heading, listed, x, y, heading
                )
                if found is not None:  # else the tree, below
                    k, s, t, lane_heading, distance, seg = found
                    return LanePosition(self._lane_list[k], s, t, lane_heading, distance, seg)
        # Scalar Python on the few segments of one grid cell beats numpy's per-call overhead.
        found = []  # (distance, u, segment)
        for k, px, py, dx, dy, len2, _ in self._grid.get(
            (math.floor(x / _GRID_CELL), math.floor(y / _GRID_CELL)), ()
        ):
            rx, ry = x - px, y - py
            u = (rx * dx + ry * dy) / len2
            u = 0.0 if u < 0.0 else 1.0 if u > 1.0 else u
            found.append((math.hypot(rx - dx * u, ry - dy * u), u, k))
        best = min(found) if found else None
        if best is None or best[0] + _TIE_DISTANCE > _GRID_REACH:
            found = self._search_tree(x, y)
            best = min(found)
        seg_lane = self._seg_lane_list
        if heading is not None:
            close = [f for f in found if f[0] <= best[0] + _TIE_DISTANCE]
            # Segments of one lane only (the usual case) leave nothing to choose.
            if any(seg_lane[f[2]] != seg_lane[best[2]] for f in close):
                headings = self._seg_heading_list
                aligned = min(close, key=lambda f: angle_between(headings[f[2]], heading))
                lane_k = seg_lane[aligned[2]]
                best = min(f for f in found if seg_lane[f[2]] == lane_k)
        distance, u, seg = best
        _, px, py, dx, dy, _, seg_len = self._seg_rows[seg]
        rx, ry = x - px, y - py
        return LanePosition(
            lane=self._lane_list[seg_lane[seg]],
            s=float(self._seg_s0_list[seg] + u * seg_len),
            t=float((dx * ry - dy * rx) / seg_len),
            heading=self._seg_heading_list[seg],
            distance=float(distance),
            segment=seg,
        )

    def _make_seg_table(self) -> np.ndarray:
        """The compiled core's rows of each index segment: start x, y, direction x, y, length
        squared, length and offset along its lane."""
        p0, d = self._seg_p0, self._seg_d
        columns = (p0[:, 0], p0[:, 1], *d.T, self._seg_len2, self._seg_len, self._seg_s0)
        self._seg_table = np.ascontiguousarray(np.stack(columns, axis=1))
        return self._seg_table

    def _search_tree(self, x: float, y: float) -> list[tuple[float, float, int]]:
        point = shapely.Point(x, y)
        _, dist = self._tree.query_nearest(point, return_distance=True)
        segs = self._tree.query(point, predicate="dwithin", distance=float(dist[0]) + _TIE_DISTANCE)
        rx = x - self._seg_p0[segs, 0]
        ry = y - self._seg_p0[segs, 1]
        dx, dy = self._seg_d[segs, 0], self._seg_d[segs, 1]
        u = np.clip((rx * dx + ry * dy) / self._seg_len2[segs], 0.0, 1.0)
        distance = np.hypot(rx - dx * u, ry - dy * u)
        return list(zip(distance.tolist(), u.tolist(), segs.tolist(), strict=True))

    def nearest_lanes(self, xy: np.ndarray) -> list[Lane]:
        """Nearest lane of each point of ``xy`` (m, 2) [m], vectorised; no heading preference
        (between lanes equally near, the search tree's pick)."""
        if len(xy) == 0:
            return []
        if len(xy) < _GRID_BATCH:
            _, seg = self._tree.query_nearest(shapely.points(xy), all_matches=False)
            lane = self._seg_lane[seg]
        else:
            lane = self._grid_lanes(xy)
            undecided = np.flatnonzero(lane < 0)
            if len(undecided):
                points = shapely.points(xy[undecided])
                _, seg = self._tree.query_nearest(points, all_matches=False)
                lane[undecided] = self._seg_lane[seg]
        lanes = self._lane_list
        return [lanes[k] for k in lane.tolist()]

    def _grid_lanes(self, xy: np.ndarray) -> np.ndarray:
        """Each point's nearest lane (its index in the lane list) from the segments of its grid
        cell, all points at once; -1 where the cell cannot tell: no segment within
        _GRID_REACH, or another lane within _GRID_MARGIN of the nearest. Anywhere else that lane
        is the search tree's answer too, whatever the last bits of either's distances."""
        cells = np.floor(xy / _GRID_CELL).astype(np.int64)
        order = np.lexsort((cells[:, 1], cells[:, 0]))  # points cell by cell
        by_cell = cells[order]
        firsts = np.flatnonzero(np.any(by_cell[1:] != by_cell[:-1], axis=1)) + 1
        grid = self._grid_segments or self._make_grid_segments()
        points, segments = [], []
        for members, cell in zip(
            np.split(order, firsts), by_cell[np.r_[0, firsts]].tolist(), strict=True
        ):
            found = grid.get((cell[0], cell[1]))
            if found is not None:  # each point's candidates side by side
                points.append(members.repeat(len(found)))
                segments.append(np.tile(found, len(members)))
        lane = np.full(len(xy), -1)
        if not points:
            return lane
        point, seg = np.concatenate(points), np.concatenate(segments)
        rx, ry = (xy[point] - self._seg_p0[seg]).T
        dx, dy = self._seg_d[seg].T
        u = np.clip((rx * dx + ry * dy) / self._seg_len2[seg], 0.0, 1.0)
        distance = np.hypot(rx - dx * u, ry - dy * u)
        starts = np.flatnonzero(np.r_[True, point[1:] != point[:-1]])
        sizes = np.diff(np.r_[starts, len(point)])
        nearest = np.minimum.reduceat(distance, starts)
        at_nearest = np.flatnonzero(distance == nearest.repeat(sizes))
        first = at_nearest[np.r_[True, point[at_nearest][1:] != point[at_nearest][:-1]]]
        seg_lane = self._seg_lane[seg]
        best = seg_lane[first]
        others = np.where(seg_lane != best.repeat(sizes), distance, np.inf)
        clear = np.minimum.reduceat(others, starts) > nearest + _GRID_MARGIN
        clear &= nearest + _GRID_MARGIN <= _GRID_REACH
        lane[point[starts][clear]] = best[clear]
        return lane

    def _make_grid_segments(self) -> dict[tuple[int, int], np.ndarray]:
        self._grid_segments = {
            cell: np.array([row[0] for row in rows]) for cell, rows in self._grid.items()
        }
        return self._grid_segments

    def is_on_road(self, x: float, y: float, near: LanePosition | None = None) -> bool:
        """Whether (x, y) [m] is inside the drivable area. ``near``, the point's
        :meth:`nearest_lane`, lets a point well inside that lane skip the polygon test."""
        if near is not None and _well_inside(near):
            return True
        return bool(shapely.contains_xy(self.drivable_area, x, y))

    def in_junction(self, x: float, y: float, near: LanePosition | None = None) -> bool:
        """Whether (x, y) [m] is inside a junction area. ``near``, the point's
        :meth:`nearest_lane`, lets a point on a lane piece clear of junctions skip the polygon
        test."""
        if self._junction_area is None:
            return False
        # The point is near.distance from an index segment: farther than that from every
        # junction, it is outside them all.
        if (
            near is not None
            and near.segment >= 0
            and self._seg_clearance[near.segment] - near.distance > _CLEARANCE_MARGIN
        ):
            return False
        return bool(shapely.contains_xy(self._junction_area, x, y))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) [m] of the drivable area."""
        return tuple(self.drivable_area.bounds)


def _well_inside(position: LanePosition) -> bool:
    """Whether a point is certainly inside its lane's surface (so inside the drivable area):
    nearer the centreline than half the lane width and level with the lane's inside, not its
    flat ends. The margins exceed GEOS' approximations of the surface (1 % line simplification
    of a buffer, polygonal round joins), so this never says True where the polygon says False."""
    lane = position.lane
    return (
        position.distance < 0.45 * lane.width - _SURFACE_MARGIN
        and _SURFACE_MARGIN < position.s < lane.length - _SURFACE_MARGIN
    )


def polygon_parts(geometry: BaseGeometry) -> list[Polygon]:
    """The non-empty polygons of any geometry: itself, the members of a MultiPolygon, the
    polygonal pieces of a GeometryCollection (a repaired self-intersecting shape is any of
    these); lines and points have no area and are dropped."""
    if isinstance(geometry, Polygon):
        return [geometry] if not geometry.is_empty else []
    if isinstance(geometry, (MultiPolygon, GeometryCollection)):
        return [part for piece in geometry.geoms for part in polygon_parts(piece)]
    return []


def lane_surface(lane: Lane) -> Polygon:
    """The lane's paved area: its centreline widened to the lane width, flat ends."""
    return LineString(lane.centreline).buffer(lane.width / 2, cap_style="flat", join_style="round")


def _segment_tree(p0: np.ndarray, d: np.ndarray) -> shapely.STRtree:
    """Search tree of the segments from ``p0`` (S, 2) along ``d`` (S, 2) [m]."""
    return shapely.STRtree(shapely.linestrings(np.stack([p0, p0 + d], 1)))


def _successors(lane) -> list[str]:
    """Lanes a vehicle enters at the end of ``lane``: the junction's internal lane when there is
    one, else the next normal lane."""
    out = []
    for conn in lane.getOutgoing():
        via = conn.getViaLaneID()
        out.append(via if via else conn.getToLane().getID())
    return list(dict.fromkeys(out))


def _split_long_segments(pts: np.ndarray, cum_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The polyline ``pts`` (n, 2) with extra vertices so no segment exceeds _MAX_SEGMENT, and the
    distance along it of each vertex."""
    s_new = [
        np.linspace(a, b, max(1, math.ceil((b - a) / _MAX_SEGMENT)) + 1)[:-1]
        for a, b in itertools.pairwise(cum_s)
    ]
    s_all = np.concatenate([*s_new, cum_s[-1:]])
    xy = np.stack([np.interp(s_all, cum_s, pts[:, 0]), np.interp(s_all, cum_s, pts[:, 1])], 1)
    return xy, s_all
