"""Writes a scenario folder: ``scenario.json``, ``map.net.xml`` and the traffic file."""

from __future__ import annotations

import shutil
from pathlib import Path

from arena.scenario import SCENARIO_FILE, DataLabel, ReplayTraffic, Scenario, SumoTraffic
from scenarios.generators import Draft, Spec

MAP_FILE = "map.net.xml"
ROUTES_FILE = "traffic.rou.xml"
TRAJECTORIES_FILE = "trajectories.csv"


def write_scenario(folder: Path, scenario: Scenario, net_path: Path) -> Scenario:
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(net_path, folder / MAP_FILE)
    (folder / SCENARIO_FILE).write_text(scenario.model_dump_json(indent=2) + "\n")
    return scenario


def write_reactive(
    folder: Path, scenario_id: str, spec: Spec, seed: int, draft: Draft, net_path: Path
) -> Scenario:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / ROUTES_FILE).write_text(draft.routes.to_xml())
    scenario = Scenario(
        id=scenario_id,
        family=spec.family,
        variant=spec.variant,
        volume=spec.volume,
        agents=len(draft.missions),
        reactive=True,
        seed=seed,
        map=MAP_FILE,
        missions=tuple(draft.missions),
        traffic=SumoTraffic(routes=ROUTES_FILE, triggers=tuple(draft.triggers)),
        label=DataLabel.synthetic,
    )
    return write_scenario(folder, scenario, net_path)


def replay_traffic(bubble_radius: float | None = None) -> ReplayTraffic:
    return ReplayTraffic(
        trajectories=TRAJECTORIES_FILE, label=DataLabel.recorded, bubble_radius=bubble_radius
    )
