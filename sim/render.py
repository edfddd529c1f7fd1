"""SVG drawings of a road network and what happens on it: lanes, vehicles as oriented boxes,
trajectories, markers.

A :class:`SvgCanvas` maps metres in the map frame (y up) to SVG pixels (y down) and collects
elements; :func:`draw_road` paints a :class:`sim.road.RoadNetwork` onto it. Scenario pictures
(``arena scenarios show``) and episode pictures (the evaluator) build on these::

    canvas = SvgCanvas.around(road)
    draw_road(canvas, road)
    canvas.vehicle(x, y, heading, 4.5, 1.8, fill=EGO_COLOUR, label="Agent_0")
    canvas.polyline(xy, stroke=EGO_COLOUR, dash="4 3")
    svg_text = canvas.to_svg()
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sim.road import RoadNetwork

ROAD_COLOUR = "#5b5f66"
JUNCTION_COLOUR = "#50545a"
SHOULDER_COLOUR = "#7d7462"
MARKING_COLOUR = "#e8e8e8"
STOP_LINE_COLOUR = "#ffffff"
BACKGROUND = "#dfe8d8"
TRAFFIC_COLOUR = "#4a90d9"
EGO_COLOUR = "#e4572e"
GOAL_COLOUR = "#2ca02c"


class SvgCanvas:
    """Map-frame drawing surface. ``bounds`` = (xmin, ymin, xmax, ymax) [m]; ``scale`` [px/m]."""

    def __init__(
        self, bounds: tuple[float, float, float, float], scale: float = 2.0, margin: float = 10.0
    ) -> None:
        xmin, ymin, xmax, ymax = bounds
        self.xmin, self.ymax = xmin - margin, ymax + margin
        self.scale = scale
        self.width = (xmax - xmin + 2 * margin) * scale
        self.height = (ymax - ymin + 2 * margin) * scale
        self.elements: list[str] = []

    @classmethod
    def around(cls, road: RoadNetwork, scale: float | None = None) -> SvgCanvas:
        """A canvas covering the whole network; the scale keeps the picture near 1200 px wide."""
        pts = np.concatenate([lane.centreline for lane in road.lanes.values()])
        xmin, ymin = pts.min(axis=0)
        xmax, ymax = pts.max(axis=0)
        if scale is None:
            scale = min(4.0, max(0.5, 1200.0 / max(xmax - xmin, ymax - ymin, 1.0)))
        return cls((float(xmin), float(ymin), float(xmax), float(ymax)), scale)

    def px(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) map points [m] -> (n, 2) SVG pixels."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        return np.column_stack(
            [(xy[:, 0] - self.xmin) * self.scale, (self.ymax - xy[:, 1]) * self.scale]
        )

    def _points(self, xy: np.ndarray) -> str:
        return " ".join(f"{px:.1f},{py:.1f}" for px, py in self.px(xy))

    def polygon(
        self,
        xy: np.ndarray,
        fill: str,
        stroke: str = "none",
        stroke_width: float = 0.0,
        opacity: float = 1.0,
    ) -> None:
        self.elements.append(
            f'<polygon points="{self._points(xy)}" fill="{fill}" stroke="{stroke}" '
            f'stroke-width="{stroke_width * self.scale:.2f}" fill-opacity="{opacity}"/>'
        )

    def polyline(
        self,
        xy: np.ndarray,
        stroke: str,
        width: float = 0.3,
        dash: str | None = None,
        opacity: float = 1.0,
    ) -> None:
        """A line through map points; ``width`` [m]; ``dash`` an SVG dash pattern in pixels."""
        dashes = f' stroke-dasharray="{dash}"' if dash else ""
        self.elements.append(
            f'<polyline points="{self._points(xy)}" fill="none" stroke="{stroke}" '
            f'stroke-width="{max(width * self.scale, 0.5):.2f}" '
            f'stroke-opacity="{opacity}"{dashes}/>'
        )

    def vehicle(
        self,
        x: float,
        y: float,
        heading: float,
        length: float,
        width: float,
        fill: str = TRAFFIC_COLOUR,
        label: str | None = None,
    ) -> None:
        """An oriented box [m] with a darker nose so the heading shows."""
        c, s = math.cos(heading), math.sin(heading)
        corners = np.array([[0.5, 0.5], [0.5, -0.5], [-0.5, -0.5], [-0.5, 0.5]]) * [length, width]
        rot = np.array([[c, -s], [s, c]])
        body = corners @ rot.T + [x, y]
        self.polygon(body, fill, stroke="#222222", stroke_width=0.15)
        nose = np.array([[0.5, 0.5], [0.5, -0.5], [0.3, -0.5], [0.3, 0.5]]) * [length, width]
        self.polygon(nose @ rot.T + [x, y], "#222222", opacity=0.6)
        if label:
            self.text(x, y + width, label, size=2.5)

    def circle(
        self,
        x: float,
        y: float,
        radius: float,
        fill: str,
        opacity: float = 0.5,
        stroke: str = "none",
    ) -> None:
        ((cx, cy),) = self.px([x, y])
        self.elements.append(
            f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{radius * self.scale:.1f}" fill="{fill}" '
            f'fill-opacity="{opacity}" stroke="{stroke}"/>'
        )

    def text(self, x: float, y: float, text: str, size: float = 3.0, fill: str = "#111111") -> None:
        """``size`` [m] of the font."""
        ((cx, cy),) = self.px([x, y])
        self.elements.append(
            f'<text x="{cx:.1f}" y="{cy:.1f}" font-size="{max(size * self.scale, 8):.1f}" '
            f'font-family="sans-serif" fill="{fill}" text-anchor="middle">{escape(text)}</text>'
        )

    def title(self, text: str) -> None:
        self.elements.append(
            '<text x="8" y="20" font-size="16" font-family="sans-serif" fill="#111111">'
            f"{escape(text)}</text>"
        )

    def to_svg(self) -> str:
        head = (
            '<svg xmlns="http://www.w3.org/2000/svg" '
            f'width="{self.width:.0f}" height="{self.height:.0f}" '
            f'viewBox="0 0 {self.width:.1f} {self.height:.1f}">'
        )
        background = f'<rect width="100%" height="100%" fill="{BACKGROUND}"/>'
        return "\n".join([head, background, *self.elements, "</svg>"]) + "\n"


def _offset(line: np.ndarray, distance: float) -> np.ndarray:
    """(n, 2) polyline shifted ``distance`` [m] to its left."""
    d = np.gradient(line, axis=0)
    norm = np.hypot(d[:, 0], d[:, 1])[:, None]
    normal = np.column_stack([-d[:, 1], d[:, 0]]) / np.maximum(norm, 1e-9)
    return line + distance * normal


def lane_outline(centreline: np.ndarray, width: float) -> np.ndarray:
    """(2n, 2) polygon of a lane surface."""
    return np.concatenate([_offset(centreline, width / 2), _offset(centreline, -width / 2)[::-1]])


@dataclass(frozen=True)
class RoadGeometry:
    """What a road map is drawn from, in map coordinates [m]: every picture of a road (SVG,
    replay page, video frames) paints these in this order."""

    junctions: tuple[np.ndarray, ...]  # (n, 2) junction areas and internal lane surfaces
    lanes: tuple[np.ndarray, ...]  # (n, 2) lane surfaces
    shoulders: tuple[np.ndarray, ...]  # (n, 2) shoulder lane surfaces
    dashed: tuple[np.ndarray, ...]  # (n, 2) dividers between lanes of one edge
    solid: tuple[np.ndarray, ...]  # (n, 2) road edges
    stop_lines: tuple[np.ndarray, ...]  # (2, 2) across the end of a lane with a stop sign


def road_geometry(road: RoadNetwork, stop_lanes: tuple[str, ...] = ()) -> RoadGeometry:
    """Junctions, lane surfaces (shoulders apart), dashed lane dividers and solid road edges, and
    a stop line across the end of each lane in ``stop_lanes``."""
    # RoadNetwork keeps junction areas as simple polygons, whatever shapes its file held.
    junctions = [np.asarray(polygon.exterior.coords) for polygon in road.junction_polygons]
    junctions += [
        lane_outline(lane.centreline, lane.width)
        for lane in road.lanes.values()
        if lane.is_internal
    ]
    normal = [lane for lane in road.lanes.values() if not lane.is_internal]
    dashed, solid, stop_lines = [], [], []
    for lane in normal:
        left = _offset(lane.centreline, lane.width / 2)
        is_leftmost = lane.index == len(road.edges[lane.edge_id]) - 1
        (solid if is_leftmost else dashed).append(left)
        if lane.index == 0:
            solid.append(_offset(lane.centreline, -lane.width / 2))
    for lane_id in stop_lanes:
        lane = road.lanes[lane_id]
        end = lane.centreline[-2:]
        d = end[1] - end[0]
        n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-9)
        p = end[1] - 0.3 * d / max(float(np.hypot(*d)), 1e-9)
        stop_lines.append(np.array([p + n * lane.width / 2, p - n * lane.width / 2]))
    return RoadGeometry(
        junctions=tuple(junctions),
        lanes=tuple(
            lane_outline(lane.centreline, lane.width) for lane in normal if not lane.is_shoulder
        ),
        shoulders=tuple(
            lane_outline(lane.centreline, lane.width) for lane in normal if lane.is_shoulder
        ),
        dashed=tuple(dashed),
        solid=tuple(solid),
        stop_lines=tuple(stop_lines),
    )


def draw_road(canvas: SvgCanvas, road: RoadNetwork, stop_lanes: tuple[str, ...] = ()) -> None:
    """Paint :func:`road_geometry` onto ``canvas``."""
    geometry = road_geometry(road, stop_lanes)
    for polygon in geometry.junctions:
        canvas.polygon(polygon, JUNCTION_COLOUR)
    for polygon in geometry.lanes:
        canvas.polygon(polygon, ROAD_COLOUR)
    for polygon in geometry.shoulders:
        canvas.polygon(polygon, SHOULDER_COLOUR)
    for line in geometry.dashed:
        canvas.polyline(line, MARKING_COLOUR, 0.15, dash="6 6")
    for line in geometry.solid:
        canvas.polyline(line, MARKING_COLOUR, 0.15)
    for line in geometry.stop_lines:
        canvas.polyline(line, STOP_LINE_COLOUR, 0.5)
