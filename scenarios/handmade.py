"""Small hand-made scenario folders: a straight road (plain node/edge XML through netconvert),
missions, background vehicles as a routes file or a recording, and a ``scenario.json`` per
``arena/scenario.py``. For the simulator's tests and benchmarks, never part of a suite."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from arena.scenario import (
    SCENARIO_FILE,
    Family,
    Goal,
    LaneChangeTrigger,
    Mission,
    ReplayTraffic,
    Scenario,
    SumoTraffic,
)

LANE_WIDTH = 3.2  # [m] netconvert default


def build_net(folder: Path, nodes: list[tuple[str, float, float]], edges: list[dict]) -> Path:
    """``map.net.xml`` from nodes (id, x, y) and edge attribute dicts, coordinates unshifted."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "map.nod.xml").write_text(
        "<nodes>"
        + "".join(f'<node id="{n}" x="{x}" y="{y}" type="priority"/>' for n, x, y in nodes)
        + "</nodes>"
    )
    (folder / "map.edg.xml").write_text(
        "<edges>"
        + "".join("<edge " + " ".join(f'{k}="{v}"' for k, v in e.items()) + "/>" for e in edges)
        + "</edges>"
    )
    net = folder / "map.net.xml"
    subprocess.run(
        [
            "netconvert",
            "--node-files",
            str(folder / "map.nod.xml"),
            "--edge-files",
            str(folder / "map.edg.xml"),
            "--offset.disable-normalization",
            "true",
            "--no-turnarounds",
            "true",
            "-o",
            str(net),
        ],
        check=True,
        capture_output=True,
    )
    return net


def straight_road(
    folder: Path, length: float = 400.0, lanes: int = 2, speed: float = 13.89
) -> Path:
    """Edge ``E`` from (0, 0) to (length, 0) with ``lanes`` lanes eastwards, and edge ``W`` with
    one lane back westwards. Lane ``E_i`` centre: y = -(lanes - i - 0.5) * 3.2; ``W_0``: +1.6."""
    return build_net(
        folder,
        [("w", 0.0, 0.0), ("e", length, 0.0)],
        [
            {"id": "E", "from": "w", "to": "e", "numLanes": lanes, "speed": speed},
            {"id": "W", "from": "e", "to": "w", "numLanes": 1, "speed": speed},
        ],
    )


def lane_y(index: int, lanes: int = 2) -> float:
    """Centre y [m] of lane ``E_index`` on :func:`straight_road`."""
    return -(lanes - index - 0.5) * LANE_WIDTH


def mission(
    agent_id: str = "Agent_0",
    start: tuple[float, float, float] = (20.0, lane_y(1), 0.0),
    goal: tuple[float, float] = (380.0, lane_y(1)),
    speed: float = 0.0,
    route: tuple[str, ...] = ("E",),
    radius: float = 2.0,
    start_step: int = 0,
) -> Mission:
    return Mission(
        agent_id=agent_id,
        start=start,
        start_speed=speed,
        start_step=start_step,
        route=route,
        goal=Goal(position=goal, radius=radius),
    )


def vehicle_xml(
    vid: str,
    depart_pos: float,
    lane: int,
    speed: float,
    route: str = "east",
    vtype: str = "car",
    depart: float = 0.0,
) -> str:
    return (
        f'<vehicle id="{vid}" type="{vtype}" route="{route}" depart="{depart}" '
        f'departPos="{depart_pos}" departLane="{lane}" departSpeed="{speed}"/>'
    )


ROUTES_HEAD = (
    '<vType id="car" length="4.5" width="1.8" sigma="0.5"/>'
    '<vType id="reckless" length="4.5" width="1.8" sigma="0" decel="0.5" emergencyDecel="0.5" '
    'apparentDecel="0.5" minGap="0" tau="0.1"/>'
    '<vType id="steady" length="4.5" width="1.8" sigma="0" speedDev="0"/>'
    '<route id="east" edges="E"/>'
)


@dataclass
class ScenarioSpec:
    """What differs between test scenarios; :func:`make_scenario` writes the folder."""

    missions: tuple[Mission, ...] = (mission(),)
    vehicles: list[str] = field(default_factory=list)  # <vehicle>/<flow> XML
    trajectories: str | None = None  # CSV text (replay traffic) instead of SUMO vehicles
    bubble_radius: float | None = None
    triggers: tuple[LaneChangeTrigger, ...] = ()
    max_episode_steps: int = 800
    seed: int = 1
    net: Callable[[Path], Path] = straight_road


def make_scenario(folder: Path, spec: ScenarioSpec | None = None) -> Path:
    spec = spec or ScenarioSpec()
    folder.mkdir(parents=True, exist_ok=True)
    net = spec.net(folder)
    if spec.trajectories is not None:
        (folder / "traffic.csv").write_text(spec.trajectories)
        traffic = ReplayTraffic(trajectories="traffic.csv", bubble_radius=spec.bubble_radius)
    else:
        (folder / "traffic.rou.xml").write_text(
            "<routes>" + ROUTES_HEAD + "".join(spec.vehicles) + "</routes>"
        )
        traffic = SumoTraffic(routes="traffic.rou.xml", triggers=spec.triggers)
    scenario = Scenario(
        id=folder.name,
        family=Family.replay if spec.trajectories is not None else Family.cruise,
        variant="test",
        agents=len(spec.missions),
        reactive=spec.trajectories is None,
        seed=spec.seed,
        max_episode_steps=spec.max_episode_steps,
        map=net.name,
        missions=spec.missions,
        traffic=traffic,
    )
    (folder / SCENARIO_FILE).write_text(scenario.model_dump_json(indent=2))
    return folder
