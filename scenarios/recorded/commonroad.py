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

An obstacle whose states are not exact poses has no trajectory to replay and is counted by what
it holds: an occupancy set or a single state, *set-valued* states (a position as a shape, an
orientation or velocity as an interval: a prediction) or *point-mass* states (velocities along x
and y, no orientation). Each obstacle's ``type`` (car, truck, bus, bicycle, pedestrian, train, ...)
is kept beside its trajectory: it decides what the vehicle can be (:mod:`.naturalistic`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arena.errors import ArenaError
from sim.trajectories import Trajectory

STEP_S = 0.1  # [s]
FORMATS = ("2018b", "2020a")
SPEED_LIMIT_SIGNS = ("R2-1", "274")  # US and German maximum-speed signs
# Where a lanelet has no limit of its own [m/s]: 65 mph (US-101's posted limit) on highways; on
# a scene tagged urban, 50 km/h, the common built-up-area limit (a US city street is posted at
# 25-35 mph, 40-56 km/h).
DEFAULT_SPEED_LIMIT = 29.0576
URBAN_SPEED_LIMIT = 13.8889


class CommonRoadImportError(ArenaError, ValueError):
    """A file that is not a usable CommonRoad scenario; the message names the file and problem."""


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
    source: str  # the file's own ``source`` attribute, e.g. "Next Generation Simulation (NGSIM)"
    tags: frozenset[str]  # scenario tags: "urban", "interstate", ...
    # CommonRoad obstacle type of each trajectory, by vehicle id ("car", "train", ...).
    types: dict[str, str] = field(default_factory=dict)
    # Obstacles that have no recorded trajectory, per what they hold instead (:data:`UNTRACKED`).
    untracked: dict[str, int] = field(default_factory=dict)


# What an obstacle without a replayable trajectory holds, by the words a skip reason uses.
UNTRACKED = ("occupancy sets only", "a single state", "set-valued states", "point-mass states")


# A state's fields and the child holding an exact value (intervals and shapes are sets).
EXACT_VALUES = (
    ("time", "exact"),
    ("position", "point"),
    ("orientation", "exact"),
    ("velocity", "exact"),
)


class _NotExact(ArenaError, ValueError):
    """A state that is not an exact pose; the message is one of :data:`UNTRACKED`."""


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
    tags = frozenset(root.get("tags", "").split()) | {t.tag for t in root.findall("scenarioTags/*")}
    default_limit = URBAN_SPEED_LIMIT if "urban" in tags else DEFAULT_SPEED_LIMIT
    try:
        dt = float(root.get("timeStepSize", ""))
        signs = _speed_signs(root)
        lanelets = tuple(
            _lanelet(el, signs, default_limit)
            for el in root.iter("lanelet")
            if el.find("leftBound") is not None
        )
        obstacles = [
            el
            for el in root
            if el.tag == "dynamicObstacle"
            or (el.tag == "obstacle" and el.findtext("role") == "dynamic")
        ]
        read = [(_trajectory(el, dt), el.findtext("type", "car").strip()) for el in obstacles]
    except (ValueError, TypeError, AttributeError) as exc:
        raise CommonRoadImportError(f"{path}: malformed CommonRoad {version}: {exc}") from exc
    trajectories = tuple(t for t, _ in read if isinstance(t, Trajectory))
    return CommonRoadScene(
        root.get("benchmarkID", path.stem),
        version,
        dt,
        lanelets,
        trajectories,
        source=root.get("source", ""),
        tags=tags,
        types={t.vehicle_id: kind for t, kind in read if isinstance(t, Trajectory)},
        untracked=dict(sorted(Counter(t for t, _ in read if isinstance(t, str)).items())),
    )


def _number(el: ET.Element, path: str, what: str) -> float:
    """The number at ``path`` under ``el``; a missing or non-numeric field raises ValueError
    naming ``what`` and the field."""
    text = el.findtext(path)
    if text is None:
        raise ValueError(f"{what} has no <{path}>")
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{what}: <{path}> is {text.strip()!r}, not a number") from None


def _points(bound: ET.Element | None, what: str) -> np.ndarray:
    if bound is None:
        raise ValueError(f"missing {what}")
    pts = [
        (_number(p, "x", f"{what} point"), _number(p, "y", f"{what} point"))
        for p in bound.findall("point")
    ]
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
                what = f"speed limit sign {sign.get('id')}"
                out[int(sign.get("id"))] = _number(element, "additionalValue", what)
    return out


def _lanelet(el: ET.Element, signs: dict[int, float], default_limit: float) -> Lanelet:
    lid = int(el.get("id"))
    left = _points(el.find("leftBound"), f"lanelet {lid} leftBound")
    right = _points(el.find("rightBound"), f"lanelet {lid} rightBound")
    if len(left) != len(right):
        raise ValueError(f"lanelet {lid}: bounds of {len(left)} and {len(right)} points")
    limits = [signs[r] for r in _refs(el, "trafficSignRef") if r in signs]
    if el.findtext("speedLimit") is not None:
        limits.append(_number(el, "speedLimit", f"lanelet {lid}"))
    return Lanelet(
        lid,
        left,
        right,
        _refs(el, "predecessor"),
        _refs(el, "successor"),
        _same_direction(el, "adjacentLeft"),
        _same_direction(el, "adjacentRight"),
        min(limits) if limits else default_limit,
    )


def _state(el: ET.Element) -> tuple[float, float, float, float, float]:
    """(time step, x, y, orientation, velocity) of a state; velocity 0 where absent. A state of
    another model raises :class:`_NotExact`."""
    what = f"the state at time step {el.findtext('time/exact')}"
    for name, exact in EXACT_VALUES:
        value = el.find(name)
        if value is not None and len(value) and value.find(exact) is None:
            raise _NotExact("set-valued states")  # an interval, a shape, a lanelet
    if el.find("orientation") is None and el.find("velocityY") is not None:
        raise _NotExact("point-mass states")
    point = el.find("position/point")
    if point is None:
        raise ValueError(f"{what} has no exact <position/point>")
    velocity = el.find("velocity/exact")
    return (
        _number(el, "time/exact", "a state"),
        _number(point, "x", what),
        _number(point, "y", what),
        _number(el, "orientation/exact", what),
        _number(el, "velocity/exact", what) if velocity is not None else 0.0,
    )


def _trajectory(obstacle: ET.Element, dt: float) -> Trajectory | str:
    """The obstacle's recorded trajectory, or what it holds instead (one of :data:`UNTRACKED`)."""
    oid = obstacle.get("id")
    initial = obstacle.find("initialState")
    if initial is None:
        raise ValueError(f"obstacle {oid} has no initialState")
    if obstacle.find("trajectory") is None:
        return UNTRACKED[0] if obstacle.find("occupancySet") is not None else UNTRACKED[1]
    try:
        states = [_state(initial), *(_state(s) for s in obstacle.findall("trajectory/state"))]
    except _NotExact as exc:
        return str(exc)
    except (ValueError, TypeError, AttributeError) as exc:
        raise ValueError(f"obstacle {oid}: {exc}") from exc
    if len(states) < 2:
        return UNTRACKED[1]
    arr = np.array(sorted(states))
    t = arr[:, 0] * dt
    heading = np.unwrap(arr[:, 3])
    rect = obstacle.find("shape/rectangle")
    length = _number(rect, "length", f"obstacle {oid} rectangle") if rect is not None else 4.5
    width = _number(rect, "width", f"obstacle {oid} rectangle") if rect is not None else 1.8
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
