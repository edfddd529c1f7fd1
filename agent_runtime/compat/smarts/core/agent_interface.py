"""SMARTS's agent interface (``smarts.core.agent_interface``): what a wrapper reads to learn which
observations the environment gives. Driving Arena builds it from ``agent.yaml``."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from smarts.core.controllers import ActionSpaceType


@dataclass(frozen=True)
class RGB:
    width: int = 256  # [px]
    height: int = 256  # [px]
    resolution: float = 50 / 256  # [m/px]


@dataclass(frozen=True)
class OGM(RGB):
    pass


@dataclass(frozen=True)
class DrivableAreaGridMap(RGB):
    pass


@dataclass(frozen=True)
class Waypoints:
    lookahead: int = 32  # waypoints ahead of the first


@dataclass(frozen=True)
class RoadWaypoints:
    horizon: int = 20  # [m] ahead of and behind the ego


@dataclass(frozen=True)
class NeighborhoodVehicles:
    radius: float | None = None  # [m]


@dataclass(frozen=True)
class Accelerometer:
    pass


@dataclass(frozen=True)
class Lidar:
    pass


@dataclass(frozen=True)
class LanePositions:
    """Asks for lane-relative (Frenet) coordinates; always given here."""


@dataclass(frozen=True)
class Signals:
    lookahead: float = 100.0  # [m]; our scenarios have no traffic signals


@dataclass(frozen=True)
class AgentsListAlive:
    agents_list: list[str]
    minimum_agents_alive_in_list: int


@dataclass(frozen=True)
class AgentsAliveDoneCriteria:
    minimum_ego_agents_alive: int | None = None
    minimum_total_agents_alive: int | None = None
    agent_lists_alive: list[AgentsListAlive] | None = None


@dataclass(frozen=True)
class EventConfiguration:
    not_moving_time: float = 60  # [s]
    not_moving_distance: float = 1  # [m]


@dataclass(frozen=True)
class DoneCriteria:
    collision: bool = True
    off_road: bool = True
    off_route: bool = False
    on_shoulder: bool = False
    wrong_way: bool = False
    not_moving: bool = False
    agents_alive: object = None


class AgentType(IntEnum):
    Full = 1
    Standard = 2
    Laner = 3
    LanerWithSpeed = 4
    Tracker = 5
    MPCTracker = 6
    TrajectoryInterpolator = 7
    Buddha = 8
    Loner = 9
    Tagger = 10
    Direct = 11


@dataclass(frozen=True)
class AgentInterface:
    """Each option is False/None when off, else its settings (or True). The 2022 names
    (``rgb``, ``ogm``, ``lidar``, ``waypoints``, ``neighborhood_vehicles``) and the later ones
    (``top_down_rgb``, ``occupancy_grid_map``, ``lidar_point_cloud``, ``waypoint_paths``,
    ``neighborhood_vehicle_states``) read the same settings."""

    action: ActionSpaceType = ActionSpaceType.TargetPose
    max_episode_steps: int | None = None
    neighborhood_vehicles: NeighborhoodVehicles | bool = True
    waypoints: Waypoints | bool = True
    road_waypoints: RoadWaypoints | bool = False
    drivable_area_grid_map: DrivableAreaGridMap | bool = False
    ogm: OGM | bool = False
    rgb: RGB | bool = False
    lidar: Lidar | bool = False
    accelerometer: Accelerometer | bool = True
    lane_positions: bool = True
    signals: bool = False
    done_criteria: DoneCriteria = field(default_factory=DoneCriteria)
    debug: bool = False

    @property
    def action_space(self) -> ActionSpaceType:
        return self.action

    @property
    def top_down_rgb(self):
        return self.rgb

    @property
    def occupancy_grid_map(self):
        return self.ogm

    @property
    def lidar_point_cloud(self):
        return self.lidar

    @property
    def waypoint_paths(self):
        return self.waypoints

    @property
    def neighborhood_vehicle_states(self):
        return self.neighborhood_vehicles
