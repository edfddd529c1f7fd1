"""Driving SMARTS 2022 observations and actions for agents written against SMARTS.

Used inside the sandbox by ``agent_runtime/main.py`` when ``agent.yaml`` says
``observation_format: smarts2022``: each native observation dict (agent interface spec)
becomes an attribute-access object with SMARTS's field names and numpy arrays, headings in
SMARTS's frame (0 = +y north, counter-clockwise), ``distance_travelled`` per step; a TargetPose
action's heading is turned back into ours. ``docs/smarts-compat.md`` lists every field.

Standard library plus numpy only, and no import of this project (it runs beside ``main.py``).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

FORMAT = "smarts2022"
TARGET_POSE_LENGTH = 4  # [x, y, heading, dt]: the only action with an absolute heading


def to_smarts_heading(heading: float) -> float:
    """Ours (0 = +x east, CCW) [rad] -> SMARTS (0 = +y north, CCW), wrapped to [-pi, pi)."""
    return (heading - math.pi / 2 + math.pi) % (2 * math.pi) - math.pi


def from_smarts_heading(heading: float) -> float:
    """SMARTS (0 = +y north, CCW) [rad] -> ours (0 = +x east, CCW), wrapped to [-pi, pi)."""
    return (heading + math.pi / 2 + math.pi) % (2 * math.pi) - math.pi


class Heading(float):
    """A heading [rad] in SMARTS's frame; a float, as SMARTS's ``Heading`` is."""


class Dimensions(NamedTuple):
    length: float  # [m]
    width: float  # [m]
    height: float  # [m]


class RefLinePoint(NamedTuple):
    s: float  # [m] along the lane
    t: float  # [m] left of the lane centre
    h: float = 0.0  # [m] height above the lane (always 0 here)


class Collision(NamedTuple):
    collidee_id: str
    collidee_owner_id: str = ""  # unknown here


class Events(NamedTuple):
    collisions: list[Collision]
    off_road: bool
    off_route: bool
    on_shoulder: bool
    wrong_way: bool
    not_moving: bool
    reached_goal: bool
    reached_max_episode_steps: bool
    agents_alive_done: bool = False  # no agents_alive done criterion here


class Start(NamedTuple):
    position: np.ndarray  # (2,) [m]
    heading: Heading


class PositionalGoal(NamedTuple):
    position: np.ndarray  # (3,) [m]
    radius: float  # [m]


class Mission(NamedTuple):
    start: Start
    goal: PositionalGoal
    route: tuple[str, ...]  # edge ids (SMARTS: route_vias); ours, not SMARTS's


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
    linear_acceleration: np.ndarray  # (3,) [m/s^2]
    angular_acceleration: np.ndarray  # (3,) [rad/s^2]
    linear_jerk: np.ndarray  # (3,) [m/s^3]
    angular_jerk: np.ndarray  # (3,) [rad/s^3]
    lane_position: RefLinePoint


class VehicleObservation(NamedTuple):
    id: str
    position: np.ndarray  # (3,) [m]
    bounding_box: Dimensions
    heading: Heading
    speed: float  # [m/s]
    road_id: str
    lane_id: str
    lane_index: int
    lane_position: RefLinePoint | None = None  # not computed for neighbours here


class Waypoint(NamedTuple):
    pos: np.ndarray  # (2,) [m]
    heading: Heading
    lane_id: str
    lane_width: float  # [m]
    speed_limit: float  # [m/s]
    lane_index: int
    lane_offset: float  # [m] along the lane


class Observation(NamedTuple):
    dt: float  # [s]
    step_count: int
    steps_completed: int
    elapsed_sim_time: float  # [s]
    events: Events
    ego_vehicle_state: EgoVehicleObservation
    under_this_agent_control: bool
    neighborhood_vehicle_states: list[VehicleObservation]
    waypoint_paths: list[list[Waypoint]]
    distance_travelled: float  # [m] this step (SMARTS), not the running total
    done: bool  # ours: the agent's last observation (SMARTS passes dones separately)
    lidar_point_cloud: None = None
    drivable_area_grid_map: Any = None
    occupancy_grid_map: Any = None
    top_down_rgb: Any = None
    road_waypoints: None = None
    via_data: None = None
    signals: None = None


def _vec3(values: list[float]) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


def _ego(ego: dict) -> EgoVehicleObservation:
    mission = ego["mission"]
    sx, sy, start_heading = mission["start"]
    goal = mission["goal"]
    return EgoVehicleObservation(
        id=ego["id"],
        position=_vec3(ego["position"]),
        bounding_box=Dimensions(*ego["bounding_box"]),
        heading=Heading(to_smarts_heading(ego["heading"])),
        speed=ego["speed"],
        steering=ego["steering"],
        yaw_rate=ego["yaw_rate"],
        road_id=ego["road_id"],
        lane_id=ego["lane_id"],
        lane_index=ego["lane_index"],
        mission=Mission(
            start=Start(np.array([sx, sy]), Heading(to_smarts_heading(start_heading))),
            goal=PositionalGoal(np.array([*goal["position"], 0.0][:3]), goal["radius"]),
            route=tuple(mission["route"]),
        ),
        linear_velocity=_vec3(ego["linear_velocity"]),
        angular_velocity=_vec3(ego["angular_velocity"]),
        linear_acceleration=_vec3(ego["linear_acceleration"]),
        angular_acceleration=_vec3(ego["angular_acceleration"]),
        linear_jerk=_vec3(ego["linear_jerk"]),
        angular_jerk=_vec3(ego["angular_jerk"]),
        lane_position=RefLinePoint(*ego["lane_position"][:2]),
    )


def _neighbour(n: dict) -> VehicleObservation:
    return VehicleObservation(
        id=n["id"],
        position=_vec3(n["position"]),
        bounding_box=Dimensions(*n["bounding_box"]),
        heading=Heading(to_smarts_heading(n["heading"])),
        speed=n["speed"],
        road_id=n["road_id"],
        lane_id=n["lane_id"],
        lane_index=n["lane_index"],
    )


def _path(path: list[dict]) -> list[Waypoint]:
    """One waypoint path, positions and headings converted for the whole path at once (a
    step's observation holds a few hundred waypoints)."""
    if not path:
        return []
    xy = np.array([w["pos"][:2] for w in path], dtype=np.float64)  # (n, 2) [m]
    ours = np.array([w["heading"] for w in path], dtype=np.float64)
    headings = ((ours - math.pi / 2 + math.pi) % (2 * math.pi) - math.pi).tolist()
    make = tuple.__new__  # skips NamedTuple's argument parsing; the fields are in order
    return [
        make(
            Waypoint,
            (
                xy[i],
                Heading(h),
                w["lane_id"],
                w["lane_width"],
                w["speed_limit"],
                w["lane_index"],
                w["lane_offset"],
            ),
        )
        for i, (w, h) in enumerate(zip(path, headings, strict=True))
    ]


class SmartsAdapter:
    """Converts one episode's observations and actions; remembers each agent's running distance
    to hand out per-step ``distance_travelled``. :meth:`reset` at every new episode."""

    def __init__(self, action_space: str = "TargetPose") -> None:
        self.action_space = action_space
        self._distance: dict[str, float] = {}  # agent id -> running total at its last step [m]

    def reset(self) -> None:
        self._distance = {}

    def observations(self, obs: dict[str, dict]) -> dict[str, Observation]:
        return {agent_id: self.observation(agent_id, o) for agent_id, o in obs.items()}

    def observation(self, agent_id: str, o: dict) -> Observation:
        total = o["distance_travelled"]
        step_distance = total - self._distance.get(agent_id, 0.0)
        self._distance[agent_id] = total
        ev = o["events"]
        return Observation(
            dt=o["dt"],
            step_count=o["step_count"],
            steps_completed=o["step_count"],
            elapsed_sim_time=o["elapsed_sim_time"],
            events=Events(
                collisions=[Collision(c) for c in ev["collisions"]],
                off_road=ev["off_road"],
                off_route=ev["off_route"],
                on_shoulder=ev["on_shoulder"],
                wrong_way=ev["wrong_way"],
                not_moving=ev["not_moving"],
                reached_goal=ev["reached_goal"],
                reached_max_episode_steps=ev["reached_max_episode_steps"],
            ),
            ego_vehicle_state=_ego(o["ego_vehicle_state"]),
            under_this_agent_control=True,
            neighborhood_vehicle_states=[_neighbour(n) for n in o["neighborhood_vehicle_states"]],
            waypoint_paths=[_path(path) for path in o["waypoint_paths"]],
            distance_travelled=step_distance,
            done=bool(o.get("done", False)),
            drivable_area_grid_map=o.get("drivable_area_grid_map"),
            occupancy_grid_map=o.get("occupancy_grid_map"),
            top_down_rgb=o.get("top_down_rgb"),
        )

    def actions(self, actions: dict[str, Any]) -> dict[str, Any]:
        """Actions back to ours: a TargetPose heading from SMARTS's frame; others unchanged."""
        if self.action_space != "TargetPose":
            return actions
        out = {}
        for agent_id, action in actions.items():
            try:
                values = np.asarray(action, dtype=np.float64).reshape(-1).tolist()
            except (TypeError, ValueError):  # malformed: the simulator says invalid_action
                out[agent_id] = action
                continue
            if len(values) == TARGET_POSE_LENGTH and math.isfinite(values[2]):
                values[2] = from_smarts_heading(values[2])
            out[agent_id] = values
        return out
