"""Picture of a scenario (``arena scenarios show``): map, lanes, stop lines, traffic at a step,
mission starts, routes and goals; for replays also the removed vehicles' recorded paths."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arena.scenario import ReplayTraffic, load_scenario
from scenarios.netinfo import net_info
from scenarios.recorded.builder import EXPERT_FILE
from sim.playback import ReplayTable
from sim.render import EGO_COLOUR, GOAL_COLOUR, SvgCanvas, draw_road
from sim.road import RoadNetwork
from sim.simulation import scene_states
from sim.trajectories import read_trajectories
from sim.vehicle.states import VehicleStates


def stop_lanes(net_path: Path) -> tuple[str, ...]:
    """Lanes whose links into a junction carry a stop sign (SUMO link state ``s``)."""
    net = net_info(net_path).net
    lanes = set()
    for edge in net.getEdges():
        for lane in edge.getLanes():
            for conn in lane.getOutgoing():
                if conn.getState() == "s":
                    lanes.add(lane.getID())
    return tuple(sorted(lanes))


def traffic_at(folder: Path, step: int) -> VehicleStates:
    """Every background vehicle at ``step``: replayed from the file, or simulated (SUMO runs in
    this process) for reactive traffic."""
    scenario = load_scenario(folder)
    if isinstance(scenario.traffic, ReplayTraffic):
        return ReplayTable(folder / scenario.traffic.trajectories, scenario.step_length).states(
            step
        )
    last = VehicleStates.empty()
    for last in scene_states(scenario, folder, max(step, 1)):  # noqa: B007  (we want the last)
        pass
    return last


def draw_scenario(folder: Path, step: int = 0) -> str:
    folder = Path(folder)
    scenario = load_scenario(folder)
    net_path = folder / scenario.map
    road = RoadNetwork.load(net_path)
    canvas = SvgCanvas.around(road)
    draw_road(canvas, road, stop_lanes(net_path))
    for m in scenario.missions:
        route = [lane for e in m.route for lane in road.edges.get(e, [])[:1]]
        for lane in route:
            canvas.polyline(lane.centreline, EGO_COLOUR, 0.4, dash="3 5", opacity=0.6)
    expert = folder / EXPERT_FILE
    if expert.exists():
        for tr in read_trajectories(expert).values():
            canvas.polyline(np.column_stack([tr.x, tr.y]), EGO_COLOUR, 0.3, opacity=0.8)
    traffic = traffic_at(folder, step)
    for i in range(len(traffic)):
        canvas.vehicle(
            float(traffic.x[i]),
            float(traffic.y[i]),
            float(traffic.heading[i]),
            float(traffic.length[i]),
            float(traffic.width[i]),
        )
    for m in scenario.missions:
        x, y, h = m.start
        canvas.vehicle(x, y, h, m.vehicle.length, m.vehicle.width, EGO_COLOUR, m.agent_id)
        gx, gy = m.goal.position
        canvas.circle(gx, gy, max(m.goal.radius, 1.0), GOAL_COLOUR, opacity=0.6, stroke="#145214")
        canvas.text(gx, gy + m.goal.radius + 1.5, f"goal {m.agent_id}", size=2.5)
    detail = " / ".join(
        str(v) for v in (scenario.family.value, scenario.variant, scenario.volume) if v
    )
    canvas.title(f"{scenario.id}  ({detail}, {scenario.label.value}, step {step})")
    return canvas.to_svg()
