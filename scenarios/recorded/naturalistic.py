"""Naturalistic replay scenarios from real recorded scenes (NGSIM via CommonRoad, or NGSIM CSV),
built as Driving SMARTS built them: one recorded vehicle is removed and a mission vehicle put at
its start state, with its goal where it ended; every other vehicle replays its recording and never
reacts.

A scene gives one scenario per *ego choice*: a recorded vehicle whose every pose fits a lane of
the built map (:mod:`scenarios.recorded.map_match`), whose path is long enough to be a task, and
whose recorded box overlaps no other recorded vehicle's (the log replay expert must be able to
solve the scenario). Scenario folders carry the source's licence and attribution.

Every scene is moved to a local frame on import: its coordinates less :func:`local_origin`, the
kilometre grid point nearest its road's centre. A georeferenced file (UTM: x ~ 686 km,
y ~ 5,335 km) then lies within a few kilometres of 0 like any other, so every limit (an action's
magnitude, a record's float32) applies to local values; a file already in local coordinates keeps
them (origin 0, 0). The origin is in the suite manifest (``naturalistic_scenes``).

A recorded road user's type decides what it can be: cars, trucks and buses are missions or traffic
(:data:`MISSION_TYPES`), other road vehicles traffic only (:data:`TRAFFIC_TYPES`), and the rest
(trains and trams, bicycles, pedestrians), which our simulation has no model of, are left out of
the replay and counted. An NGSIM CSV's ``v_Class`` says motorcycle, car or truck; without it
every vehicle is a car.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sumolib

from arena.errors import ArenaError
from arena.scenario import (
    GOAL_RADIUS_M,
    DataLabel,
    Family,
    Goal,
    Mission,
    ReplayTraffic,
    Scenario,
    VehicleDims,
)
from scenarios.recorded.builder import EXPERT_FILE, TAIL_S, _crop
from scenarios.recorded.commonroad import (
    DEFAULT_SPEED_LIMIT,
    CommonRoadImportError,
    Lanelet,
    read_scene,
)
from scenarios.recorded.lanelet_net import build_lanelet_net
from scenarios.recorded.map_match import driven_route, fit_trajectory
from scenarios.recorded.ngsim import NgsimFormatError, ngsim_types, read_ngsim
from scenarios.recorded.provenance import Provenance, attribution, provenance
from scenarios.writer import TRAJECTORIES_FILE, write_scenario
from sim.geometry import boxes_overlap
from sim.road.network import RoadNetwork
from sim.trajectories import Trajectory, write_trajectories

MIN_PATH_S = 2.0  # [s] shorter recordings are no task
MIN_TRAVEL_M = 3 * GOAL_RADIUS_M  # [m] start to goal, so a mission never starts inside its goal
TURN_RAD = math.radians(45.0)
ATTRIBUTION_FILE = "ATTRIBUTION.md"
NGSIM_LANE_WIDTH = 12 * 0.3048  # [m] the US-101 / I-80 lanes are 12 ft wide
SCENE_SUFFIXES = (".xml", ".csv")
LOCAL_GRID_M = 1000.0  # [m] a local origin is a point of this grid
# CommonRoad obstacle types (an NGSIM CSV's vehicles are all cars): what a road user can be.
MISSION_TYPES = frozenset({"car", "truck", "bus", "taxi"})
TRAFFIC_TYPES = MISSION_TYPES | {"motorcycle", "priorityVehicle", "parkedVehicle", "unknown"}


class NaturalisticImportError(ArenaError, ValueError):
    """A scene file that cannot be used; the message names the file and the problem."""


@dataclass(frozen=True)
class NaturalisticScene:
    name: str
    source_file: Path
    lanelets: tuple[Lanelet, ...]
    trajectories: tuple[Trajectory, ...]  # the replayed road users, in the local frame
    provenance: Provenance
    origin: tuple[float, float] = (0.0, 0.0)  # [m] the file's coordinates of the local 0, 0
    types: dict[str, str] = dataclasses.field(default_factory=dict)  # by vehicle id; else car
    left_out: dict[str, int] = dataclasses.field(default_factory=dict)  # road users, per type
    # Obstacles without a recorded trajectory, per what they hold instead (not replayed).
    untracked: dict[str, int] = dataclasses.field(default_factory=dict)

    @property
    def variant_prefix(self) -> str:
        """``ngsim`` for NGSIM scenes (scenario variants ``ngsim_cruise`` ...), else ``corpus``."""
        return "ngsim" if self.provenance.source == "NGSIM" else "corpus"


@dataclass(frozen=True)
class Ego:
    vehicle_id: str
    kind: str  # cruise, lane_change, merge, left_turn, right_turn
    route: tuple[str, ...]


@dataclass(frozen=True)
class Skipped:
    """A scene file a corpus build could not use, and why."""

    file: str
    reason: str


@dataclass(frozen=True)
class SceneFolder:
    scenes: list[NaturalisticScene]  # usable scenes, in file-name order
    skipped: list[Skipped]


def load_scene(
    path: Path, label: DataLabel | None = None, licence: Path | None = None
) -> NaturalisticScene:
    """One scene file in its local frame; provenance from the file and the licence file beside
    it unless ``label`` / ``licence`` say otherwise. An unusable file raises
    :class:`NaturalisticImportError` naming it and the problem."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".xml":
            cr = read_scene(path)
            prov = provenance(cr.source, path.parent, label=label, licence=licence)
            name, lanelets, trajectories, types = (
                cr.benchmark_id,
                cr.lanelets,
                cr.trajectories,
                cr.types,
            )
            untracked = cr.untracked
        elif path.suffix.lower() == ".csv":
            trajectories = tuple(read_ngsim(path))
            prov = provenance("", path.parent, csv=True, label=label, licence=licence)
            name, lanelets, untracked = path.stem, ngsim_lanelets(path), {}
            types = ngsim_types(path)
        else:
            raise NaturalisticImportError(f"{path}: not a CommonRoad .xml or NGSIM .csv scene")
    except (CommonRoadImportError, NgsimFormatError) as exc:
        raise NaturalisticImportError(str(exc)) from exc
    if not lanelets:
        raise NaturalisticImportError(f"{path}: the scene has no road (no lanelets)")
    kinds = {t.vehicle_id: types.get(t.vehicle_id, "car") for t in trajectories}
    replayed = tuple(t for t in trajectories if kinds[t.vehicle_id] in TRAFFIC_TYPES)
    left_out = Counter(kind for kind in kinds.values() if kind not in TRAFFIC_TYPES)
    if not replayed:
        what = [f"{n} with {kind}" for kind, n in untracked.items()]
        what += [f"{n} of type {kind}, not replayed" for kind, n in sorted(left_out.items())]
        total = sum(untracked.values()) + sum(left_out.values())
        detail = f" ({total} obstacles without one: {', '.join(what)})" if what else ""
        raise NaturalisticImportError(
            f"{path}: the scene has no recorded vehicle trajectory{detail}"
        )
    origin = local_origin(lanelets)
    return NaturalisticScene(
        name,
        path,
        tuple(_moved_lanelet(ln, origin) for ln in lanelets),
        tuple(_moved_trajectory(t, origin) for t in replayed),
        prov,
        origin,
        {t.vehicle_id: kinds[t.vehicle_id] for t in replayed},
        dict(sorted(left_out.items())),
        untracked,
    )


def local_origin(lanelets: Sequence[Lanelet]) -> tuple[float, float]:
    """The point of the :data:`LOCAL_GRID_M` grid nearest the centre of the road's bounding box
    [m]: 0, 0 for a file already in local coordinates."""
    points = np.concatenate([np.concatenate([ln.left, ln.right]) for ln in lanelets])
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    x, y = np.round(centre / LOCAL_GRID_M) * LOCAL_GRID_M + 0.0  # + 0.0: no -0.0
    return float(x), float(y)


def _moved_lanelet(ln: Lanelet, origin: tuple[float, float]) -> Lanelet:
    if origin == (0.0, 0.0):
        return ln
    return dataclasses.replace(ln, left=ln.left - origin, right=ln.right - origin)


def _moved_trajectory(tr: Trajectory, origin: tuple[float, float]) -> Trajectory:
    if origin == (0.0, 0.0):
        return tr
    return dataclasses.replace(tr, x=tr.x - origin[0], y=tr.y - origin[1])


def scene_files(folder: Path) -> list[Path]:
    """Every ``.xml`` / ``.csv`` file of ``folder`` in name order (other files are ignored)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise NaturalisticImportError(f"{folder}: not a folder of naturalistic scenes")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SCENE_SUFFIXES)
    if not files:
        raise NaturalisticImportError(f"{folder}: holds no CommonRoad .xml or NGSIM .csv scene")
    return files


def load_scenes(
    folder: Path, label: DataLabel | None = None, licence: Path | None = None
) -> SceneFolder:
    """Every usable scene of ``folder``; a file that cannot be used is skipped with its reason."""
    scenes, skipped = [], []
    for path in scene_files(folder):
        try:
            scenes.append(load_scene(path, label, licence))
        except NaturalisticImportError as exc:
            skipped.append(Skipped(path.name, str(exc).removeprefix(f"{path}: ")))
    return SceneFolder(scenes, skipped)


def ngsim_lanelets(path: Path) -> tuple[Lanelet, ...]:
    """NGSIM CSV has no road geometry: straight parallel 12 ft lanes along +x, one per
    ``Lane_ID`` (1 = leftmost, at y = 0 .. -12 ft, as :func:`read_ngsim` lays out ``Local_X``),
    spanning the recorded x range."""
    try:
        with open(path, newline="") as f:
            lane_ids = {int(float(row["Lane_ID"])) for row in csv.DictReader(f)}
    except ValueError as exc:
        raise NaturalisticImportError(f"{path}: Lane_ID is not a lane number: {exc}") from exc
    if min(lane_ids) < 1:
        raise NaturalisticImportError(f"{path}: Lane_ID {min(lane_ids)} (NGSIM lanes count from 1)")
    trajectories = read_ngsim(path)
    x0 = min(float(t.x.min()) for t in trajectories) - 20.0
    x1 = max(float(t.x.max()) for t in trajectories) + 20.0
    n = max(lane_ids)
    out = []
    for lane_id in range(1, n + 1):
        top, bottom = -(lane_id - 1) * NGSIM_LANE_WIDTH, -lane_id * NGSIM_LANE_WIDTH
        out.append(
            Lanelet(
                id=lane_id,
                left=np.array([[x0, top], [x1, top]]),
                right=np.array([[x0, bottom], [x1, bottom]]),
                predecessors=(),
                successors=(),
                adjacent_left=lane_id - 1 if lane_id > 1 else None,
                adjacent_right=lane_id + 1 if lane_id < n else None,
                speed_limit=DEFAULT_SPEED_LIMIT,
            )
        )
    return tuple(out)


def scene_net(scene: NaturalisticScene, cache_dir: Path) -> Path:
    return build_lanelet_net(scene.name, scene.lanelets, Path(cache_dir) / "naturalistic")


def _kind(tr: Trajectory, route: tuple[str, ...], fits, net: sumolib.net.Net) -> str:
    """The manoeuvre: a turn by the heading change, a merge when the route joins a road from a
    narrower side road (an on-ramp), a lane change when it drove more lanes than edges."""
    turn = float(np.unwrap(tr.heading)[-1] - np.unwrap(tr.heading)[0])
    if turn > TURN_RAD:
        return "left_turn"
    if turn < -TURN_RAD:
        return "right_turn"
    if any(_joins_from_the_side(net, a, b) for a, b in itertools.pairwise(route)):
        return "merge"
    lanes = {(f.lane.edge_id, f.lane.index) for f in fits if not f.lane.is_internal}
    return "lane_change" if len(lanes) > len(route) else "cruise"


def _joins_from_the_side(net: sumolib.net.Net, edge: str, nxt: str) -> bool:
    """Whether ``edge`` feeds ``nxt`` beside a wider road that feeds it too."""
    ours = net.getEdge(edge)
    feeders = [e for e in net.getEdge(nxt).getIncoming() if e.getID() != edge]
    return any(e.getLaneNumber() > ours.getLaneNumber() for e in feeders)


def collides(ego: Trajectory, others: Sequence[Trajectory]) -> str | None:
    """The id of the first recorded vehicle whose box overlaps ``ego``'s box at a common time,
    boxes of any length (a 20 m truck too); None when there is none."""
    for other in others:
        common = np.intersect1d(np.round(ego.time, 1), np.round(other.time, 1))
        if len(common) == 0:
            continue
        ia = np.round((common - ego.time[0]) / 0.1).astype(int)
        ib = np.round((common - other.time[0]) / 0.1).astype(int)
        # Boxes farther apart than their half diagonals together cannot touch.
        reach = (math.hypot(ego.length, ego.width) + math.hypot(other.length, other.width)) / 2
        near = np.hypot(ego.x[ia] - other.x[ib], ego.y[ia] - other.y[ib]) <= reach
        if not near.any():
            continue
        ia, ib = ia[near], ib[near]
        if boxes_overlap(ego.corners(ia), other.corners(ib)).any():
            return other.vehicle_id
    return None


# Why a recorded vehicle makes no mission (counted per reason by a corpus build).
REJECTIONS = {
    "traffic_only": "a road vehicle other than a car, truck or bus: replayed, never a mission",
    "not_replayed": "a train or tram, bicycle or pedestrian: left out of the replay",
    "no_trajectory": "no exact recorded trajectory (an occupancy set, a single state, set-valued "
    "or point-mass states): left out of the replay",
    "short": f"recorded for less than {MIN_PATH_S} s or travels less than {MIN_TRAVEL_M} m",
    "off_lanes": "a recorded pose fits no lane of the built map",
    "off_road": "its recorded centre leaves the built road surface",
    "starts_in_junction": "it starts inside a junction",
    "collision": "its recorded box overlaps another recorded vehicle's",
}


def screen_egos(scene: NaturalisticScene, net_path: Path) -> tuple[list[Ego], Counter]:
    """Every recorded vehicle of ``scene`` whose recorded drive finishes its mission on our map
    by the checks of an evaluation (on the road surface, no collision), in vehicle-id order;
    and how many were rejected per reason of :data:`REJECTIONS`."""
    road = RoadNetwork.load(net_path)
    net = sumolib.net.readNet(str(net_path), withInternal=False)
    out: list[Ego] = []
    rejected: Counter = Counter()
    if scene.left_out:
        rejected["not_replayed"] = sum(scene.left_out.values())
    if scene.untracked:
        rejected["no_trajectory"] = sum(scene.untracked.values())
    for tr in sorted(scene.trajectories, key=lambda t: t.vehicle_id):
        reason = None
        fits, route = None, None
        if scene.types.get(tr.vehicle_id, "car") not in MISSION_TYPES:
            reason = "traffic_only"
        elif tr.time[-1] - tr.time[0] < MIN_PATH_S - 1e-6 or (
            math.hypot(tr.x[-1] - tr.x[0], tr.y[-1] - tr.y[0]) < MIN_TRAVEL_M
        ):
            reason = "short"
        else:
            fits = fit_trajectory(road, tr)
            route = driven_route(net, fits)
            if route is None:
                reason = "off_lanes"
            elif not all(road.is_on_road(x, y) for x, y in zip(tr.x, tr.y, strict=True)):
                reason = "off_road"
            elif _starts_in_junction(road, tr):
                reason = "starts_in_junction"
            elif collides(tr, [o for o in scene.trajectories if o.vehicle_id != tr.vehicle_id]):
                reason = "collision"
        if reason is not None:
            rejected[reason] += 1
            continue
        out.append(Ego(tr.vehicle_id, _kind(tr, route, fits, net), route))
    return out, rejected


def _starts_in_junction(road: RoadNetwork, tr: Trajectory) -> bool:
    x, y, h = float(tr.x[0]), float(tr.y[0]), float(tr.heading[0])
    near = road.nearest_lane(x, y, h)
    return near.lane.is_internal or road.in_junction(x, y, near)


def ego_choices(scene: NaturalisticScene, net_path: Path) -> list[Ego]:
    """Every recorded vehicle of ``scene`` that makes a solvable mission (:func:`screen_egos`)."""
    return screen_egos(scene, net_path)[0]


def write_naturalistic(
    folder: Path,
    scenario_id: str,
    scene: NaturalisticScene,
    ego: Ego,
    net_path: Path,
    seed: int,
) -> Scenario:
    """A non-reactive replay of ``scene`` without ``ego``'s vehicle, which the mission takes over;
    time 0 is the ego's first recorded frame."""
    full = next(t for t in scene.trajectories if t.vehicle_id == ego.vehicle_id)
    t0, t1 = float(full.time[0]), float(full.time[-1])
    me = _crop(full, t0, t1)
    assert me is not None
    others = [
        c
        for t in scene.trajectories
        if t.vehicle_id != ego.vehicle_id and (c := _crop(t, t0, t1 + TAIL_S)) is not None
    ]
    mission = Mission(
        agent_id="Agent_0",
        start=(round(me.x[0], 3), round(me.y[0], 3), round(me.heading[0], 5)),
        start_speed=round(float(me.speed[0]), 3),
        start_step=0,
        route=ego.route,
        goal=Goal(position=(round(me.x[-1], 3), round(me.y[-1], 3))),
        vehicle=VehicleDims(length=me.length, width=me.width),
    )
    folder.mkdir(parents=True, exist_ok=True)
    write_trajectories(folder / TRAJECTORIES_FILE, others)
    write_trajectories(
        folder / EXPERT_FILE,
        [Trajectory("Agent_0", me.time, me.x, me.y, me.heading, me.speed, me.length, me.width)],
    )
    (folder / ATTRIBUTION_FILE).write_text(
        attribution(
            scene.provenance, scene.name, scene.source_file.name, ego.vehicle_id, scene.origin
        )
    )
    scenario = Scenario(
        id=scenario_id,
        family=Family.replay,
        variant=f"{scene.variant_prefix}_{ego.kind}",
        volume=None,
        agents=1,
        reactive=False,
        seed=seed,
        map="map.net.xml",
        missions=(mission,),
        traffic=ReplayTraffic(trajectories=TRAJECTORIES_FILE, label=scene.provenance.label),
        label=scene.provenance.label,
    )
    return write_scenario(folder, scenario, net_path)


def shipped_scenes_dir(configured: Path | None) -> Path:
    """The naturalistic scenes shipped with the package, with their licence and provenance:
    ``scenarios/data/naturalistic/commonroad-ngsim``, unless ``configured`` (the setting
    ``ARENA_NATURALISTIC_DIR``) names others."""
    if configured is not None:
        return configured
    return Path(__file__).resolve().parents[1] / "data" / "naturalistic" / "commonroad-ngsim"
