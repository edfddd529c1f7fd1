"""Naturalistic replay scenarios from real recorded scenes (NGSIM via CommonRoad, or NGSIM CSV),
built as Driving SMARTS built them: one recorded vehicle is removed and a mission vehicle put at
its start state, with its goal where it ended; every other vehicle replays its recording and never
reacts.

A scene gives one scenario per *ego choice*: a recorded vehicle whose every pose fits a lane of
the built map (:mod:`scenarios.recorded.map_match`), whose path is long enough to be a task, and
whose recorded box overlaps no other recorded vehicle's (the log replay expert must be able to
solve the scenario). Scenario folders carry the source's licence and attribution.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sumolib

from arena.config import get_settings
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
from scenarios.recorded.commonroad import CommonRoadImportError, Lanelet, read_scene
from scenarios.recorded.geometry import boxes_overlap
from scenarios.recorded.lanelet_net import build_lanelet_net
from scenarios.recorded.map_match import driven_route, fit_trajectory
from scenarios.recorded.ngsim import NgsimFormatError, read_ngsim
from scenarios.writer import TRAJECTORIES_FILE, write_scenario
from sim.road.network import RoadNetwork
from sim.trajectories import Trajectory, write_trajectories

MIN_PATH_S = 2.0  # [s] shorter recordings are no task
MIN_TRAVEL_M = 3 * GOAL_RADIUS_M  # [m] start to goal, so a mission never starts inside its goal
TURN_RAD = math.radians(45.0)
ATTRIBUTION_FILE = "ATTRIBUTION.md"
SOURCE = "NGSIM"
NGSIM_LANE_WIDTH = 12 * 0.3048  # [m] the US-101 / I-80 lanes are 12 ft wide


class NaturalisticImportError(ArenaError, ValueError):
    """A scene file that cannot be used; the message names the file and the problem."""


@dataclass(frozen=True)
class NaturalisticScene:
    name: str
    source_file: Path
    lanelets: tuple[Lanelet, ...]
    trajectories: tuple[Trajectory, ...]


@dataclass(frozen=True)
class Ego:
    vehicle_id: str
    kind: str  # cruise, lane_change, left_turn, right_turn
    route: tuple[str, ...]


def load_scene(path: Path) -> NaturalisticScene:
    path = Path(path)
    try:
        if path.suffix.lower() == ".xml":
            cr = read_scene(path)
            scene = NaturalisticScene(cr.benchmark_id, path, cr.lanelets, cr.trajectories)
        elif path.suffix.lower() == ".csv":
            trajectories = tuple(read_ngsim(path))
            scene = NaturalisticScene(path.stem, path, ngsim_lanelets(path), trajectories)
        else:
            raise NaturalisticImportError(f"{path}: not a CommonRoad .xml or NGSIM .csv scene")
    except (CommonRoadImportError, NgsimFormatError) as exc:
        raise NaturalisticImportError(str(exc)) from exc
    if not scene.lanelets:
        raise NaturalisticImportError(f"{path}: the scene has no road (no lanelets)")
    if not scene.trajectories:
        raise NaturalisticImportError(f"{path}: the scene has no recorded vehicle trajectory")
    return scene


def load_scenes(folder: Path) -> list[NaturalisticScene]:
    """Every ``.xml`` / ``.csv`` scene of ``folder`` in name order (other files are ignored)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise NaturalisticImportError(f"{folder}: not a folder of naturalistic scenes")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".xml", ".csv"))
    if not files:
        raise NaturalisticImportError(f"{folder}: holds no CommonRoad .xml or NGSIM .csv scene")
    return [load_scene(p) for p in files]


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
                speed_limit=29.0576,  # [m/s] 65 mph
            )
        )
    return tuple(out)


def scene_net(scene: NaturalisticScene, cache_dir: Path) -> Path:
    return build_lanelet_net(scene.name, scene.lanelets, Path(cache_dir) / "naturalistic")


def _kind(tr: Trajectory, route: tuple[str, ...], fits) -> str:
    turn = float(np.unwrap(tr.heading)[-1] - np.unwrap(tr.heading)[0])
    if turn > TURN_RAD:
        return "left_turn"
    if turn < -TURN_RAD:
        return "right_turn"
    lanes = {(f.lane.edge_id, f.lane.index) for f in fits if not f.lane.is_internal}
    return "lane_change" if len(lanes) > len(route) else "cruise"


def _collides(ego: Trajectory, others: list[Trajectory]) -> bool:
    for other in others:
        common = np.intersect1d(np.round(ego.time, 1), np.round(other.time, 1))
        if len(common) == 0:
            continue
        ia = np.round((common - ego.time[0]) / 0.1).astype(int)
        ib = np.round((common - other.time[0]) / 0.1).astype(int)
        near = np.hypot(ego.x[ia] - other.x[ib], ego.y[ia] - other.y[ib]) < 8.0
        if not near.any():
            continue
        ia, ib = ia[near], ib[near]
        a = np.column_stack(
            [
                ego.x[ia],
                ego.y[ia],
                ego.heading[ia],
                np.full(len(ia), ego.length),
                np.full(len(ia), ego.width),
            ]
        )
        b = np.column_stack(
            [
                other.x[ib],
                other.y[ib],
                other.heading[ib],
                np.full(len(ib), other.length),
                np.full(len(ib), other.width),
            ]
        )
        if boxes_overlap(a, b).any():
            return True
    return False


def ego_choices(scene: NaturalisticScene, net_path: Path) -> list[Ego]:
    """Every recorded vehicle of ``scene`` that makes a solvable mission, in vehicle-id order."""
    road = RoadNetwork.load(net_path)
    net = sumolib.net.readNet(str(net_path), withInternal=False)
    out = []
    for tr in sorted(scene.trajectories, key=lambda t: t.vehicle_id):
        if tr.time[-1] - tr.time[0] < MIN_PATH_S - 1e-6:
            continue
        if math.hypot(tr.x[-1] - tr.x[0], tr.y[-1] - tr.y[0]) < MIN_TRAVEL_M:
            continue
        fits = fit_trajectory(road, tr)
        route = driven_route(net, fits)
        if route is None:
            continue
        others = [o for o in scene.trajectories if o.vehicle_id != tr.vehicle_id]
        if _collides(tr, others):
            continue
        out.append(Ego(tr.vehicle_id, _kind(tr, route, fits), route))
    return out


def attribution(scene: NaturalisticScene, vehicle_id: str) -> str:
    """Provenance and licence text shipped in every naturalistic scenario folder."""
    licence = scene.source_file.parent / "LICENSE.txt"
    text = (
        f"# Source: {SOURCE} naturalistic driving data\n\n"
        f"Scene `{scene.name}` (file `{scene.source_file.name}`); the mission vehicle replaces "
        f"recorded vehicle `{vehicle_id}`.\n\n"
        "- Trajectories: NGSIM, US Department of Transportation (public domain).\n"
        "- CommonRoad conversion and road geometry: Technical University of Munich, BSD 3-Clause "
        "(below); road geometry partly derived from OpenStreetMap: "
        "(c) OpenStreetMap contributors (ODbL).\n"
    )
    if licence.exists():
        text += "\n## Licence\n\n" + licence.read_text()
    return text


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
    (folder / ATTRIBUTION_FILE).write_text(attribution(scene, ego.vehicle_id))
    scenario = Scenario(
        id=scenario_id,
        family=Family.replay,
        variant=f"ngsim_{ego.kind}",
        volume=None,
        agents=1,
        reactive=False,
        seed=seed,
        map="map.net.xml",
        missions=(mission,),
        traffic=ReplayTraffic(trajectories=TRAJECTORIES_FILE, label=DataLabel.naturalistic),
        label=DataLabel.naturalistic,
    )
    return write_scenario(folder, scenario, net_path)


def shipped_scenes_dir() -> Path:
    """The naturalistic scenes shipped with the package, with their licence and provenance:
    ``scenarios/data/naturalistic/commonroad-ngsim`` (setting ``ARENA_NATURALISTIC_DIR``
    overrides)."""
    configured = get_settings().naturalistic_dir
    if configured is not None:
        return configured
    return Path(__file__).resolve().parents[1] / "data" / "naturalistic" / "commonroad-ngsim"
