"""Importer for CommonRoad scenario XML, formats 2018b and 2020a: the recorded trajectories and the
road (lanelets).

Read with the standard library's XML parser rather than ``commonroad-io``, whose current releases
open 2020a files only. The two formats differ in what we read as follows:

- dynamic obstacles are ``<obstacle>`` with ``<role>dynamic</role>`` (2018b) or
  ``<dynamicObstacle>`` (2020a); both carry ``initialState`` plus ``trajectory/state`` with
  ``position/point``, ``orientation/exact``, ``time/exact`` (steps), ``velocity/exact``;
- speed limits are ``<speedLimit>`` inside a lanelet (2018b) or a traffic sign ``R2-1`` / ``274``
  with its value in ``additionalValue`` referenced by ``trafficSignRef`` (2020a) [m/s].

CommonRoad positions are already the shape centre in metres and orientations are radians
counter-clockwise from +x, as ours. Scenarios stepped at another rate than 0.1 s are resampled by
linear interpolation.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena.errors import ArenaError
from sim.trajectories import Trajectory

STEP_S = 0.1  # [s]
FORMATS = ("2018b", "2020a")
SPEED_LIMIT_SIGNS = ("R2-1", "274")  # US and German maximum-speed signs
DEFAULT_SPEED_LIMIT = 29.0576  # [m/s] 65 mph, US-101's posted limit, where a lanelet has none


class CommonRoadImportError(ArenaError, ValueError):
    pass


@dataclass(frozen=True)
class Lanelet:
    """One lanelet: a lane piece between two polylines of equal point count, driven from the
    first point to the last."""

    id: int
    left: np.ndarray  # (n, 2) [m]
    right: np.ndarray  # (n, 2) [m]
    predecessors: tuple[int, ...]
    successors: tuple[int, ...]
    adjacent_left: int | None  # only neighbours driven in the same direction
    adjacent_right: int | None
    speed_limit: float  # [m/s]

    @property
    def centre(self) -> np.ndarray:
        """(n, 2) centre line [m]."""
        return (self.left + self.right) / 2

    @property
    def width(self) -> float:
        """Mean distance between the bounds [m]."""
        return float(np.hypot(*(self.left - self.right).T).mean())


@dataclass(frozen=True)
class CommonRoadScene:
    benchmark_id: str
    version: str  # "2018b" or "2020a"
    dt: float  # [s]
    lanelets: tuple[Lanelet, ...]
    trajectories: tuple[Trajectory, ...]  # resampled to STEP_S


def read_commonroad(path: Path) -> list[Trajectory]:
    return list(read_scene(path).trajectories)


def read_scene(path: Path) -> CommonRoadScene:
    """The lanelets and trajectories of one CommonRoad file; a malformed file raises
    :class:`CommonRoadImportError` naming the file and the problem."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise CommonRoadImportError(f"{path}: not a readable CommonRoad scenario: {exc}") from exc
    if root.tag != "commonRoad":
        raise CommonRoadImportError(
            f"{path}: not a readable CommonRoad scenario: root <{root.tag}>"
        )
    version = root.get("commonRoadVersion", "")
    if version not in FORMATS:
        raise CommonRoadImportError(
            f"{path}: CommonRoad format {version!r} is not supported (known: {', '.join(FORMATS)})"
        )
    try:
        dt = float(root.get("timeStepSize", ""))
        signs = _speed_signs(root)
        lanelets = tuple(_lanelet(el, signs) for el in root.iter("lanelet") if el.find("leftBound"))
        obstacles = [
            el
            for el in root
            if el.tag == "dynamicObstacle"
            or (el.tag == "obstacle" and el.findtext("role") == "dynamic")
        ]
        trajectories = tuple(t for t in (_trajectory(el, dt) for el in obstacles) if t is not None)
    except (ValueError, TypeError, AttributeError) as exc:
        raise CommonRoadImportError(f"{path}: malformed CommonRoad {version}: {exc}") from exc
    return CommonRoadScene(root.get("benchmarkID", path.stem), version, dt, lanelets, trajectories)


def _points(bound: ET.Element | None, what: str) -> np.ndarray:
    if bound is None:
        raise ValueError(f"missing {what}")
    pts = [(float(p.findtext("x")), float(p.findtext("y"))) for p in bound.findall("point")]
    if len(pts) < 2:
        raise ValueError(f"{what} has fewer than two points")
    return np.array(pts)


def _refs(el: ET.Element, tag: str) -> tuple[int, ...]:
    return tuple(int(r.get("ref")) for r in el.findall(tag))


def _same_direction(el: ET.Element, tag: str) -> int | None:
    adj = el.find(tag)
    return int(adj.get("ref")) if adj is not None and adj.get("drivingDir") == "same" else None


def _speed_signs(root: ET.Element) -> dict[int, float]:
    out = {}
    for sign in root.iter("trafficSign"):
        for element in sign.findall("trafficSignElement"):
            if element.findtext("trafficSignID") in SPEED_LIMIT_SIGNS:
                out[int(sign.get("id"))] = float(element.findtext("additionalValue"))
    return out


def _lanelet(el: ET.Element, signs: dict[int, float]) -> Lanelet:
    lid = int(el.get("id"))
    left = _points(el.find("leftBound"), f"lanelet {lid} leftBound")
    right = _points(el.find("rightBound"), f"lanelet {lid} rightBound")
    if len(left) != len(right):
        raise ValueError(f"lanelet {lid}: bounds of {len(left)} and {len(right)} points")
    limits = [signs[r] for r in _refs(el, "trafficSignRef") if r in signs]
    if el.findtext("speedLimit") is not None:
        limits.append(float(el.findtext("speedLimit")))
    return Lanelet(
        lid,
        left,
        right,
        _refs(el, "predecessor"),
        _refs(el, "successor"),
        _same_direction(el, "adjacentLeft"),
        _same_direction(el, "adjacentRight"),
        min(limits) if limits else DEFAULT_SPEED_LIMIT,
    )


def _state(el: ET.Element) -> tuple[float, float, float, float, float]:
    """(time step, x, y, orientation, velocity) of a state; velocity 0 where absent."""
    point = el.find("position/point")
    if point is None:
        raise ValueError("a state without an exact position")
    return (
        float(el.findtext("time/exact")),
        float(point.findtext("x")),
        float(point.findtext("y")),
        float(el.findtext("orientation/exact")),
        float(el.findtext("velocity/exact") or 0.0),
    )


def _trajectory(obstacle: ET.Element, dt: float) -> Trajectory | None:
    oid = obstacle.get("id")
    initial = obstacle.find("initialState")
    if initial is None:
        raise ValueError(f"obstacle {oid} has no initialState")
    states = [_state(initial), *(_state(s) for s in obstacle.findall("trajectory/state"))]
    if len(states) < 2:
        return None
    arr = np.array(sorted(states))
    t = arr[:, 0] * dt
    heading = np.unwrap(arr[:, 3])
    rect = obstacle.find("shape/rectangle")
    length = float(rect.findtext("length")) if rect is not None else 4.5
    width = float(rect.findtext("width")) if rect is not None else 1.8
    grid = np.round(np.arange(t[0], t[-1] + 1e-9, STEP_S), 1)
    h = np.interp(grid, t, heading)
    return Trajectory(
        vehicle_id=f"cr{oid}",
        time=grid,
        x=np.interp(grid, t, arr[:, 1]),
        y=np.interp(grid, t, arr[:, 2]),
        heading=(h + np.pi) % (2 * np.pi) - np.pi,
        speed=np.interp(grid, t, arr[:, 4]),
        length=length,
        width=width,
    )
