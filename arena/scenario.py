"""The scenario format: one folder per scenario holding ``scenario.json`` and the files it names.

This model is the contract between the scenario generators (which write it) and the simulator
(which reads it). Paths inside are relative to the scenario folder. Coordinates are metres in the
map frame; headings are radians, 0 along +x, counter-clockwise positive.
"""

from __future__ import annotations

import hashlib
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

SCENARIO_FILE = "scenario.json"


class Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Family(StrEnum):
    """Scoring breakdown families (scoring spec: per-family metrics)."""

    cruise = "cruise"
    overtake = "overtake"
    merge = "merge"
    cut_in = "cut_in"
    left_turn_t = "left_turn_t"
    turn_c = "turn_c"
    replay = "replay"


class DataLabel(StrEnum):
    """Provenance of traffic. Our own recordings are never called naturalistic."""

    synthetic = "synthetic"
    recorded = "recorded"
    naturalistic = "naturalistic"


# The one goal radius of generated and replayed scenarios; the record stores each mission's own.
GOAL_RADIUS_M = 2.5


class Goal(Frozen):
    position: tuple[float, float]  # [m]
    radius: float = GOAL_RADIUS_M  # [m]


class VehicleDims(Frozen):
    length: float = 4.5  # [m]
    width: float = 1.8  # [m]
    height: float = 1.5  # [m]


class Mission(Frozen):
    agent_id: str  # "Agent_0", "Agent_1", ...
    start: tuple[float, float, float]  # x [m], y [m], heading [rad]
    start_speed: float = 0.0  # [m/s]
    start_step: int = 0  # the vehicle enters the simulation at this step (start delay)
    route: tuple[str, ...]  # SUMO edge ids from start to goal
    goal: Goal
    vehicle: VehicleDims = VehicleDims()


class LaneChangeTrigger(Frozen):
    """Scripted aggressive manoeuvre: when ``vehicle`` is within ``gap_m`` ahead of the agent
    (longitudinally, on an adjacent lane), it is forced into the agent's lane over
    ``duration_s``."""

    vehicle: str
    agent_id: str
    gap_m: float
    duration_s: float = 1.0


class SumoTraffic(Frozen):
    """Reactive background traffic driven by SUMO."""

    kind: Literal["sumo"] = "sumo"
    routes: str  # relative path to a SUMO .rou.xml (vTypes, routes, flows, vehicles)
    triggers: tuple[LaneChangeTrigger, ...] = ()


class ReplayTraffic(Frozen):
    """Recorded trajectories replayed exactly. With ``bubble_radius`` set, recorded vehicles that
    come within that distance of a mission vehicle switch to SUMO control for the rest of the
    episode (replay with reactive bubble)."""

    kind: Literal["replay"] = "replay"
    trajectories: str  # relative path to a trajectory file (docs/scenarios.md)
    label: DataLabel = DataLabel.recorded
    bubble_radius: float | None = None  # [m]


Traffic = Annotated[SumoTraffic | ReplayTraffic, Field(discriminator="kind")]


class Scenario(Frozen):
    id: str
    family: Family
    variant: str
    volume: str | None = None
    agents: int
    reactive: bool
    seed: int
    max_episode_steps: int = 800
    step_length: float = 0.1  # [s]
    map: str  # relative path to the SUMO .net.xml
    missions: tuple[Mission, ...]
    traffic: Traffic
    label: DataLabel = DataLabel.synthetic
    # The solvability rule: an expert completes every scenario, or this says why not.
    unsolvable_reason: str | None = None


def load_scenario(folder: Path) -> Scenario:
    return Scenario.model_validate_json((Path(folder) / SCENARIO_FILE).read_text())


def content_hash(folder: Path) -> str:
    """sha256 over every file of a scenario folder (relative names and bytes, sorted by name)."""
    folder = Path(folder)
    digest = hashlib.sha256()
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()
