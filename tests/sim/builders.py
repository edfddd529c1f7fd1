"""Small scenario folders for simulator tests (:mod:`scenarios.handmade`), a real short episode
and broken junction outlines."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from scenarios.handmade import (
    LANE_WIDTH,
    ROUTES_HEAD,
    ScenarioSpec,
    build_net,
    lane_y,
    make_scenario,
    mission,
    straight_road,
    vehicle_xml,
)


def recorded_episode(root: Path) -> tuple[Path, Path]:
    """A real short episode (libsumo in this process): ``Agent_0`` drives at 10 m/s into a slow
    car ahead in its lane, ``Agent_1`` cruises beside it until the 60-step limit, and two cars
    pass. Returns (the suite folder holding the scenario ``two_lanes``, the record)."""
    from sim.episode import run_episode
    from sim.interface import ActionSpace, AgentInterface
    from tests.sim.agents import ScriptedAgent, drive_straight

    folder = make_scenario(
        root / "suite" / "two_lanes",
        ScenarioSpec(
            missions=(
                mission("Agent_0", start=(20.0, lane_y(1), 0.0)),
                mission("Agent_1", start=(20.0, lane_y(0), 0.0), goal=(380.0, lane_y(0))),
            ),
            vehicles=[
                '<vType id="crawler" length="4.5" width="1.8" sigma="0" maxSpeed="2"/>',
                '<route id="west" edges="W"/>',
                vehicle_xml("slow", 45.0, 1, 2.0, vtype="crawler"),
                vehicle_xml("fast", 60.0, 0, 12.0),
                vehicle_xml("oncoming", 300.0, 0, 13.0, route="west"),
            ],
            max_episode_steps=60,
        ),
    )
    record = root / "records" / "two_lanes.npz"
    agent = ScriptedAgent(drive_straight(10.0))
    interface = AgentInterface(action_space=ActionSpace.TargetPose)
    run_episode(folder, agent, interface, record_path=record)
    return folder.parent, record


# Junction outlines a network file may hold that are not valid polygons: repairing them gives a
# MultiPolygon, a polygon with a line sticking out (GeometryCollection) or a polygon with a hole.
INVALID_JUNCTION_SHAPES: dict[str, list[tuple[float, float]]] = {
    "bow_tie": [(-8, -8), (8, 8), (8, -8), (-8, 8)],
    "two_lobes_touching": [(-8, 0), (0, 8), (0, 0), (8, 8), (8, -8), (0, 0), (0, -8)],
    "spike": [(-8, -8), (8, -8), (8, 8), (0, 8), (0, 20), (0, 8), (-8, 8)],
    "ring": [
        (-8, -8),
        (8, -8),
        (8, 8),
        (-8, 8),
        (-8, -8),
        (-4, -4),
        (-4, 4),
        (4, 4),
        (4, -4),
        (-4, -4),
    ],
}


def with_junction_shape(net_path: Path, junction_id: str, shape: list[tuple[float, float]]) -> Path:
    """Rewrite the outline of junction ``junction_id`` of a SUMO network file in place to
    ``shape`` [m] around the junction's centre."""
    tree = ET.parse(net_path)
    node = tree.getroot().find(f"junction[@id='{junction_id}']")
    cx, cy = float(node.get("x")), float(node.get("y"))
    node.set("shape", " ".join(f"{cx + x:.2f},{cy + y:.2f}" for x, y in shape))
    tree.write(net_path)
    return net_path


__all__ = [
    "INVALID_JUNCTION_SHAPES",
    "LANE_WIDTH",
    "ROUTES_HEAD",
    "ScenarioSpec",
    "build_net",
    "lane_y",
    "make_scenario",
    "mission",
    "recorded_episode",
    "straight_road",
    "vehicle_xml",
    "with_junction_shape",
]
