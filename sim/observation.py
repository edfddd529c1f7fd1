"""The observation dict an agent receives, exactly as ``docs/agent-interface.md`` lists it.

Plain Python values (lists, floats, ints, bools, strings), plus the optional rasters as uint8 numpy
arrays (``sim.bev``), which the sandbox protocol carries as arrays.
An agent's bounding box and mission are built once per episode and shared between observations
(waypoints are built afresh, level with the vehicle):
an in-process policy must treat observations as read-only.
"""

from __future__ import annotations

import numpy as np

from agent_runtime.packed_waypoints import PackedPaths
from sim.events import Events
from sim.interface import AgentInterface
from sim.mission_vehicle import MissionVehicle, Status
from sim.road import Lane, LanePosition, RoadNetwork
from sim.vehicle.states import VehicleStates

RASTERS = ("drivable_area_grid_map", "occupancy_grid_map", "top_down_rgb")
DEFAULT_HEIGHT = 1.5  # [m] of vehicles whose height we do not know


def build_observation(
    *,
    vehicle: MissionVehicle,
    step: int,
    dt: float,
    lane: LanePosition,
    events: Events,
    neighbours: VehicleStates,
    road: RoadNetwork,
    waypoint_paths: list[list[dict]] | PackedPaths,
    interface: AgentInterface,
    rasters: dict[str, np.ndarray] | None = None,
    lidar: dict[str, np.ndarray] | None = None,
    road_waypoints: dict[str, list[list[dict]]] | None = None,
) -> dict:
    pose, k = vehicle.pose, vehicle.kinematics
    constant = vehicle.constant_observation or _constant_parts(vehicle)
    obs = {
        "dt": dt,
        "step_count": step,
        "elapsed_sim_time": round(step * dt, 6),
        "distance_travelled": vehicle.distance_travelled,
        "done": vehicle.status is Status.done,  # True once: the agent's last observation
        "events": events.as_observation(),
        "ego_vehicle_state": {
            "id": vehicle.id,
            "position": [pose.x, pose.y, 0.0],
            "heading": pose.heading,
            "speed": pose.speed,
            "bounding_box": constant["bounding_box"],
            "steering": pose.steering,
            "yaw_rate": k.yaw_rate,
            "road_id": lane.lane.edge_id,
            "lane_id": lane.lane.id,
            "lane_index": lane.lane.index,
            "lane_position": [lane.s, lane.t],
            "linear_velocity": [*k.velocity, 0.0],
            "angular_velocity": [0.0, 0.0, k.yaw_rate],
            "linear_acceleration": [*k.acceleration, 0.0],
            "angular_acceleration": [0.0, 0.0, k.angular_acceleration],
            "linear_jerk": [*k.jerk, 0.0],
            "angular_jerk": [0.0, 0.0, k.angular_jerk],
            "mission": constant["mission"],
        },
        "neighborhood_vehicle_states": neighbour_states(
            neighbours, road, lane_positions=interface.observation_format == "smarts2022"
        ),
        "waypoint_paths": waypoint_paths,
    }
    for name in RASTERS:
        if getattr(interface, name):
            obs[name] = rasters[name] if rasters else None
    if interface.lidar_point_cloud:
        obs["lidar_point_cloud"] = lidar
    if interface.road_waypoints:
        obs["road_waypoints"] = road_waypoints
    return obs


def _constant_parts(vehicle: MissionVehicle) -> dict:
    """The parts of ``vehicle``'s observations that never change, built at its first one."""
    mission = vehicle.mission
    vehicle.constant_observation.update(
        bounding_box=[mission.vehicle.length, mission.vehicle.width, mission.vehicle.height],
        mission={
            "start": list(mission.start),
            "goal": {"position": list(mission.goal.position), "radius": mission.goal.radius},
            "route": list(mission.route),
        },
    )
    return vehicle.constant_observation


def neighbour_states(
    neighbours: VehicleStates, road: RoadNetwork, *, lane_positions: bool = False
) -> list[dict]:
    """Neighbour dicts; lanes SUMO did not report come from our nearest-lane query. With
    ``lane_positions`` each also has ``lane_position`` [s, t] [m] on its lane (SMARTS's
    ``VehicleObservation.lane_position``; the smarts2022 format only, as it costs a projection
    per neighbour and step)."""
    out = []
    lanes = neighbour_lanes(neighbours, road)
    # Every neighbour's values in one tolist (rows of x, y, heading, speed, length, width).
    for vid, lane, (x, y, heading, speed, length, width) in zip(
        neighbours.ids, lanes, neighbours.values.tolist(), strict=True
    ):
        state = {
            "id": vid,
            "position": [x, y, 0.0],
            "heading": heading,
            "speed": speed,
            "bounding_box": [length, width, DEFAULT_HEIGHT],
            "road_id": lane.edge_id,
            "lane_id": lane.id,
            "lane_index": lane.index,
        }
        if lane_positions:
            s, t, _ = lane.project(x, y)
            state["lane_position"] = [s, t]
        out.append(state)
    return out


def neighbour_lanes(neighbours: VehicleStates, road: RoadNetwork) -> list[Lane]:
    """Each neighbour's lane: SUMO's, else (replayed and unreported vehicles) the nearest."""
    found = list(map(road.lanes.get, neighbours.lane_id))
    if None in found:  # Lanes compare by identity: a cheap scan, in C
        unknown = [i for i, lane in enumerate(found) if lane is None]
        xy = neighbours.values[unknown, :2]
        for i, lane in zip(unknown, road.nearest_lanes(xy), strict=True):
            found[i] = lane
    return found
