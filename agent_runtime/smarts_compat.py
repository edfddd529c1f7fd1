"""Driving SMARTS 2022 observations and actions for agents written against SMARTS.

Used inside the sandbox by ``agent_runtime/main.py`` when ``agent.yaml`` says
``observation_format: smarts2022``: each native observation dict (``docs/agent-interface.md``)
becomes SMARTS's own types (``smarts.core.sensors.Observation`` and the rest, from the compat
package in ``compat/``, which this module puts on ``sys.path``), headings in SMARTS's frame
(0 = +y north, counter-clockwise), ``distance_travelled`` per step, rasters as ``TopDownRGB`` /
``OccupancyGridMap`` / ``DrivableAreaGridMap`` with their metadata; a TargetPose action's heading
is turned back into ours. A policy module that defines ``submitted_wrappers()`` (the competition
kit's hook) is served through those wrappers around :class:`SandboxEnv`, as the competition's
evaluation did. ``docs/smarts-compat.md`` lists every field.

Standard library plus numpy only, and no import of this project (it runs beside ``main.py``).
"""

from __future__ import annotations

import hashlib
import math
import os
import sys
from typing import Any, ClassVar

import numpy as np

FORMAT = "smarts2022"
TARGET_POSE_LENGTH = 4  # [x, y, heading, dt]: the only action with an absolute heading
# The folder of the ``smarts`` and ``gym`` compat packages. Appended: a submission's own
# (or its installed requirements') smarts or gym comes first.
COMPAT_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "compat")
if COMPAT_DIR not in sys.path:
    sys.path.append(COMPAT_DIR)

# After the path above: these are the compat package's (or the submission's own) modules.
from smarts.core.agent_interface import (  # noqa: E402
    OGM,
    RGB,
    AgentInterface,
    Waypoints,
)
from smarts.core.agent_interface import DrivableAreaGridMap as DrivableAreaSetting  # noqa: E402
from smarts.core.agent_interface import RoadWaypoints as RoadWaypointsSetting  # noqa: E402
from smarts.core.controllers import ActionSpaceType  # noqa: E402
from smarts.core.coordinates import Dimensions, Heading, Point, RefLinePoint  # noqa: E402
from smarts.core.events import Collision, Events  # noqa: E402
from smarts.core.plan import Mission, PositionalGoal, Start  # noqa: E402
from smarts.core.road_map import make_waypoint  # noqa: E402
from smarts.core.sensors import (  # noqa: E402
    DrivableAreaGridMap,
    EgoVehicleObservation,
    GridMapMetadata,
    Observation,
    OccupancyGridMap,
    RoadWaypoints,
    TopDownRGB,
    VehicleObservation,
    Vias,
)
from smarts.zoo.agent_spec import AgentSpec  # noqa: E402

HALF_PI = math.pi / 2
TWO_PI = 2 * math.pi


def to_smarts_heading(heading: float) -> float:
    """Ours (0 = +x east, CCW) [rad] -> SMARTS (0 = +y north, CCW), wrapped to [-pi, pi)."""
    return (heading - HALF_PI + math.pi) % TWO_PI - math.pi


def from_smarts_heading(heading: float) -> float:
    """SMARTS (0 = +y north, CCW) [rad] -> ours (0 = +x east, CCW), wrapped to [-pi, pi)."""
    return (heading + HALF_PI + math.pi) % TWO_PI - math.pi


def _vec3(values: list[float]) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


def _lane_position(values: list[float] | None) -> RefLinePoint | None:
    return None if values is None else RefLinePoint(*values[:2])


def _mission(mission: dict) -> Mission:
    sx, sy, start_heading = mission["start"]
    goal = mission["goal"]
    route = tuple(mission["route"])
    return Mission(
        start=Start(np.array([sx, sy]), Heading(to_smarts_heading(start_heading))),
        goal=PositionalGoal(Point(*goal["position"][:2], 0.0), goal["radius"]),
        route_vias=route[1:-1],
        route=route,
    )


def smarts_vehicle_id(agent_id: str) -> str:
    """The id of ``agent_id``'s vehicle as SMARTS named it, ``<agent id>-<8 hex digits>``
    (agents that parse it, e.g. ``id.split("-")[0]``, find their agent id). SMARTS drew the
    digits at random; these come from the agent id, so an episode replays identically."""
    return f"{agent_id}-{hashlib.sha256(agent_id.encode()).hexdigest()[:8]}"


def _neighbour(n: dict, vehicle_id: str) -> VehicleObservation:
    return VehicleObservation(
        id=vehicle_id,
        position=_vec3(n["position"]),
        bounding_box=Dimensions(*n["bounding_box"]),
        heading=Heading(to_smarts_heading(n["heading"])),
        speed=n["speed"],
        road_id=n["road_id"],
        lane_id=n["lane_id"],
        lane_index=n["lane_index"],
        lane_position=_lane_position(n.get("lane_position")),
    )


def _path(path: list[dict]) -> list:
    """One waypoint path, positions and headings converted for the whole path at once (a
    step's observation holds a few hundred waypoints); a path still packed is read without
    making its dicts (``WaypointPath.unread``: the same values)."""
    if not path:
        return []
    unread = getattr(path, "unread", None)
    packed = unread() if unread is not None else None
    if packed is not None:
        return _packed_path(*packed)
    xy = np.array([w["pos"][:2] for w in path], dtype=np.float64)  # (n, 2) [m]
    ours = np.array([w["heading"] for w in path], dtype=np.float64)
    headings = ((ours - HALF_PI + math.pi) % TWO_PI - math.pi).tolist()
    return [
        make_waypoint(
            xy[i],
            Heading(h),
            w["lane_id"],
            w["lane_width"],
            w["speed_limit"],
            w["lane_index"],
            w["lane_offset"],
        )
        for i, (w, h) in enumerate(zip(path, headings, strict=True))
    ]


def _packed_path(values: memoryview, runs: list[tuple]) -> list:
    """:func:`_path` of a packed path: ``values`` x, y, heading, lane offset of each point."""
    points = np.frombuffer(values, dtype=np.float64).reshape(-1, 4)
    xy = points[:, :2].copy()  # (n, 2) [m], the policy's own
    headings = ((points[:, 2] - HALF_PI + math.pi) % TWO_PI - math.pi).tolist()
    offsets = points[:, 3].tolist()
    lanes = [run for run in runs for _ in range(run[-1])]
    return [
        make_waypoint(xy[i], Heading(h), lane_id, width, speed_limit, lane_index, offset)
        for i, (h, offset, (lane_id, lane_index, width, speed_limit, _)) in enumerate(
            zip(headings, offsets, lanes, strict=True)
        )
    ]


def _lidar(lidar: dict | None):
    """SMARTS's ``(point_cloud, hits, [(ray_origin, ray_end)])``: a miss's point is inf."""
    if lidar is None:
        return None
    points = np.asarray(lidar["points"], dtype=np.float64)  # (rays, 3) [m]
    hits = np.asarray(lidar["hits"], dtype=bool)
    points[~hits] = np.inf
    origins = np.asarray(lidar["origins"], dtype=np.float64)
    ends = np.asarray(lidar["ends"], dtype=np.float64)
    return list(points), hits.tolist(), list(zip(origins, ends, strict=True))


class SmartsAdapter:
    """Converts one episode's observations and actions; remembers each agent's running distance
    to hand out per-step ``distance_travelled``. :meth:`reset` at every new episode."""

    def __init__(
        self, action_space: str = "TargetPose", img_pixels: int = 256, img_meters: float = 64.0
    ) -> None:
        self.action_space = action_space
        self.resolution = img_meters / img_pixels  # [m/px]
        self._distance: dict[str, float] = {}  # agent id -> running total at its last step [m]
        self._steps: dict[str, int] = {}  # agent id -> its steps so far
        self._missions: dict[str, tuple[int, Mission]] = {}  # built once per episode
        self._agents: set[str] = set()  # the episode's agent ids: their vehicles get SMARTS ids

    def reset(self) -> None:
        self._distance, self._steps, self._missions, self._agents = {}, {}, {}, set()

    def observations(self, obs: dict[str, dict]) -> dict[str, Observation]:
        self._agents.update(obs)
        return {agent_id: self.observation(agent_id, o) for agent_id, o in obs.items()}

    def _vehicle_id(self, vehicle_id: str) -> str:
        return smarts_vehicle_id(vehicle_id) if vehicle_id in self._agents else vehicle_id

    def _collision(self, collidee: str) -> Collision:
        owner = collidee if collidee in self._agents else ""
        return Collision(self._vehicle_id(collidee), owner)

    def observation(self, agent_id: str, o: dict) -> Observation:
        total = o["distance_travelled"]
        step_distance = total - self._distance.get(agent_id, 0.0)
        self._distance[agent_id] = total
        steps = self._steps.get(agent_id, -1) + 1
        self._steps[agent_id] = steps
        self._agents.add(agent_id)
        ev = o["events"]
        ego = o["ego_vehicle_state"]
        rasters = self._rasters(o, ego)
        return Observation(
            dt=o["dt"],
            step_count=o["step_count"],
            steps_completed=steps,
            elapsed_sim_time=o["elapsed_sim_time"],
            events=Events(
                collisions=[self._collision(c) for c in ev["collisions"]],
                off_road=ev["off_road"],
                off_route=ev["off_route"],
                on_shoulder=ev["on_shoulder"],
                wrong_way=ev["wrong_way"],
                not_moving=ev["not_moving"],
                reached_goal=ev["reached_goal"],
                reached_max_episode_steps=ev["reached_max_episode_steps"],
            ),
            ego_vehicle_state=self._ego(agent_id, ego),
            under_this_agent_control=True,
            neighborhood_vehicle_states=[
                _neighbour(n, self._vehicle_id(n["id"])) for n in o["neighborhood_vehicle_states"]
            ],
            waypoint_paths=[_path(path) for path in o["waypoint_paths"]],
            distance_travelled=step_distance,
            lidar_point_cloud=_lidar(o.get("lidar_point_cloud")),
            road_waypoints=self._road_waypoints(o.get("road_waypoints")),
            via_data=Vias(near_via_points=[], hit_via_points=[]),
            done=bool(o.get("done", False)),
            **rasters,
        )

    def _ego(self, agent_id: str, ego: dict) -> EgoVehicleObservation:
        mission = ego["mission"]
        cached = self._missions.get(agent_id)
        if cached is None or cached[0] != id(mission):
            cached = (id(mission), _mission(mission))
            self._missions[agent_id] = cached
        return EgoVehicleObservation(
            id=smarts_vehicle_id(agent_id),
            position=_vec3(ego["position"]),
            bounding_box=Dimensions(*ego["bounding_box"]),
            heading=Heading(to_smarts_heading(ego["heading"])),
            speed=ego["speed"],
            steering=ego["steering"],
            yaw_rate=ego["yaw_rate"],
            road_id=ego["road_id"],
            lane_id=ego["lane_id"],
            lane_index=ego["lane_index"],
            mission=cached[1],
            linear_velocity=_vec3(ego["linear_velocity"]),
            angular_velocity=_vec3(ego["angular_velocity"]),
            linear_acceleration=_vec3(ego["linear_acceleration"]),
            angular_acceleration=_vec3(ego["angular_acceleration"]),
            linear_jerk=_vec3(ego["linear_jerk"]),
            angular_jerk=_vec3(ego["angular_jerk"]),
            lane_position=_lane_position(ego["lane_position"]),
        )

    def _rasters(self, o: dict, ego: dict) -> dict[str, Any]:
        """The rasters the observation holds, with SMARTS's metadata: grid maps get a channel
        axis (height, width, 1), as SMARTS's."""
        out: dict[str, Any] = {}
        kinds = (
            ("top_down_rgb", TopDownRGB),
            ("occupancy_grid_map", OccupancyGridMap),
            ("drivable_area_grid_map", DrivableAreaGridMap),
        )
        for name, kind in kinds:
            data = o.get(name)
            if data is None:
                continue
            data = np.asarray(data)
            if data.ndim == 2:
                data = data[:, :, None]
            metadata = GridMapMetadata(
                created_at=round(o["elapsed_sim_time"] * 1000),
                resolution=self.resolution,
                width=data.shape[1],
                height=data.shape[0],
                camera_pos=tuple(float(v) for v in ego["position"][:3]),
                camera_heading_in_degrees=math.degrees(to_smarts_heading(ego["heading"])),
            )
            out[name] = kind(metadata=metadata, data=data)
        return out

    @staticmethod
    def _road_waypoints(lanes: dict[str, list[list[dict]]] | None) -> RoadWaypoints | None:
        if lanes is None:
            return None
        return RoadWaypoints(
            lanes={lane_id: [_path(p) for p in paths] for lane_id, paths in lanes.items()}
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


def agent_interface(options: dict[str, Any], action_space: str) -> AgentInterface:
    """SMARTS's ``AgentInterface`` for the options ``agent.yaml`` chose (what wrappers read)."""
    pixels = int(options.get("img_pixels", 256))
    raster = {"width": pixels, "height": pixels}
    raster["resolution"] = float(options.get("img_meters", 64.0)) / pixels
    return AgentInterface(
        action=ActionSpaceType[action_space],
        neighborhood_vehicles=True,
        waypoints=Waypoints(lookahead=int(options.get("waypoints_per_path", 50))),
        road_waypoints=RoadWaypointsSetting() if options.get("road_waypoints") else False,
        drivable_area_grid_map=(
            DrivableAreaSetting(**raster) if options.get("drivable_area_grid_map") else False
        ),
        ogm=OGM(**raster) if options.get("occupancy_grid_map") else False,
        rgb=RGB(**raster) if options.get("top_down_rgb") else False,
        lidar=bool(options.get("lidar_point_cloud")),
        accelerometer=True,
    )


class EpisodeOver(Exception):
    """The evaluator ended the episode (a ``reset`` came where an ``act`` was awaited)."""


class SandboxEnv:
    """The environment a competition-kit policy's wrappers wrap: ``reset`` returns the first
    observations of an episode, ``step(actions)`` hands the actions to the evaluator and returns
    the next observations, with SMARTS's (rewards, dones, infos) beside them. ``io`` is the
    runtime's side: ``io.first_observations()`` the episode's first observations,
    ``io.answer(actions)`` sends actions, ``io.next()`` waits for the next act's observations
    (converted by the adapter) or raises :class:`EpisodeOver`. When every agent of an act is
    done the episode is over for the wrappers (``dones["__all__"]``) and the act is answered
    here with no actions, as SMARTS asks for none after its last step. ``options``: agent.yaml's
    (``format_obs_keys``)."""

    metadata: ClassVar[dict[str, Any]] = {"render.modes": []}
    reward_range = (-float("inf"), float("inf"))
    spec = None
    action_space = None
    observation_space = None

    def __init__(
        self, io, interfaces: dict[str, AgentInterface], options: dict[str, Any] | None = None
    ) -> None:
        self.io = io
        self.agent_interfaces = interfaces
        # Which names FormatObs gives its keys: comp-1's or later SMARTS's (agent.yaml's option).
        self.format_obs_keys = (options or {}).get("format_obs_keys", "comp-1")
        self.agent_specs = {k: AgentSpec(interface=v) for k, v in interfaces.items()}
        self.agent_ids = set(interfaces)

    def reset(self, **kwargs) -> dict[str, Observation]:
        return self.io.first_observations()

    def step(self, actions: dict[str, Any]):
        self.io.answer(actions)
        try:
            obs = self.io.next()
        except EpisodeOver:
            return {}, {}, {"__all__": True}, {}
        dones = {agent_id: o.done for agent_id, o in obs.items()}
        dones["__all__"] = bool(obs) and all(o.done for o in obs.values())
        if dones["__all__"]:
            self.io.answer({})
        rewards = {agent_id: o.distance_travelled for agent_id, o in obs.items()}
        infos = {
            agent_id: {"score": o.distance_travelled, "env_obs": o} for agent_id, o in obs.items()
        }
        return obs, rewards, dones, infos

    def seed(self, seed=None) -> list:
        return [seed]

    def render(self, mode: str = "human"):
        return None

    def close(self) -> None:
        pass

    @property
    def unwrapped(self) -> SandboxEnv:
        return self
