"""SMARTS's observation types (``smarts.core.sensors``), field for field as the 2022 competition
delivered them. Driving Arena fills them in ``agent_runtime/smarts_compat.py``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from smarts.core.coordinates import Dimensions, Heading, RefLinePoint
from smarts.core.events import Collision, Events
from smarts.core.plan import Mission
from smarts.core.road_map import Waypoint

# What SMARTS reports for a vehicle on no lane.
LANE_ID_CONSTANT = "off_lane"
ROAD_ID_CONSTANT = "off_road"
LANE_INDEX_CONSTANT = -1

__all__ = [
    "Collision",
    "DrivableAreaGridMap",
    "EgoVehicleObservation",
    "Events",
    "GridMapMetadata",
    "Observation",
    "OccupancyGridMap",
    "RoadWaypoints",
    "SignalObservation",
    "TopDownRGB",
    "VehicleObservation",
    "ViaPoint",
    "Vias",
]


class VehicleObservation(NamedTuple):
    id: str
    position: np.ndarray  # (3,) [m], centre of the box's bottom face
    bounding_box: Dimensions
    heading: Heading
    speed: float  # [m/s]
    road_id: str
    lane_id: str
    lane_index: int
    lane_position: RefLinePoint | None = None


class EgoVehicleObservation(NamedTuple):
    id: str
    position: np.ndarray  # (3,) [m]
    bounding_box: Dimensions
    heading: Heading
    speed: float  # [m/s]
    steering: float  # [rad]
    yaw_rate: float  # [rad/s]
    road_id: str
    lane_id: str
    lane_index: int
    mission: Mission
    linear_velocity: np.ndarray  # (3,) [m/s]
    angular_velocity: np.ndarray  # (3,) [rad/s]
    linear_acceleration: np.ndarray | None  # (3,) [m/s^2]
    angular_acceleration: np.ndarray | None  # (3,) [rad/s^2]
    linear_jerk: np.ndarray | None  # (3,) [m/s^3]
    angular_jerk: np.ndarray | None  # (3,) [rad/s^3]
    lane_position: RefLinePoint | None = None


class RoadWaypoints(NamedTuple):
    """Waypoint paths of every lane near the ego: lane id -> paths."""

    lanes: dict[str, list[list[Waypoint]]]


class GridMapMetadata(NamedTuple):
    created_at: int  # [ms] of simulation time
    resolution: float  # [m/px]
    width: int  # [px]
    height: int  # [px]
    camera_pos: tuple[float, float, float]  # [m]
    camera_heading_in_degrees: float  # SMARTS frame (0 = north, counter-clockwise)


class TopDownRGB(NamedTuple):
    metadata: GridMapMetadata
    data: np.ndarray  # (height, width, 3) uint8


class OccupancyGridMap(NamedTuple):
    metadata: GridMapMetadata
    data: np.ndarray  # (height, width, 1) uint8, 255 = occupied


class DrivableAreaGridMap(NamedTuple):
    metadata: GridMapMetadata
    data: np.ndarray  # (height, width, 1) uint8, 255 = drivable


class ViaPoint(NamedTuple):
    position: tuple[float, float]
    lane_index: int
    road_id: str
    required_speed: float


class Vias(NamedTuple):
    near_via_points: list[ViaPoint]
    hit_via_points: list[ViaPoint]


class SignalObservation(NamedTuple):
    state: int
    stop_point: tuple[float, float]
    controlled_lanes: list[str]
    last_changed: float | None


@dataclass
class Observation:
    dt: float  # [s] of the last step
    step_count: int  # steps of the simulation so far
    steps_completed: int  # steps this agent took
    elapsed_sim_time: float  # [s]
    events: Events
    ego_vehicle_state: EgoVehicleObservation
    under_this_agent_control: bool
    neighborhood_vehicle_states: list[VehicleObservation] | None
    waypoint_paths: list[list[Waypoint]] | None
    distance_travelled: float  # [m] in the last step
    # (point_cloud, hits, [(ray_origin, ray_end)]): 300 rays of 20 m around the ego
    lidar_point_cloud: tuple[list, list, list] | None = None
    drivable_area_grid_map: DrivableAreaGridMap | None = None
    occupancy_grid_map: OccupancyGridMap | None = None
    top_down_rgb: TopDownRGB | None = None
    road_waypoints: RoadWaypoints | None = None
    via_data: Vias | None = None
    signals: list[SignalObservation] | None = None
    # Not SMARTS's: True on the agent's last observation (SMARTS returns dones beside it).
    done: bool = False
    extras: Any = None
