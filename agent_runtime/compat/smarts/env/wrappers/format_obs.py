"""The competition kit's ``FormatObs``: SMARTS observations as dicts of fixed-shape numpy arrays
(the ``StdObs`` of ``smarts.env.wrappers.format_obs``), one per agent.

The keys are those of SMARTS ``comp-1``, the branch the 2022 competition shipped: every agent gets
``dist``, ``ego``, ``events`` and ``mission``; each option the agent interface turns on adds its
entry: ``dagm``, ``lidar`` (300 rays), ``neighbors`` (10 nearest, zero-padded), ``ogm``, ``rgb``,
``waypoints`` (4 paths of 20, zero-padded). Later SMARTS releases renamed them
(``distance_travelled``, ``ego_vehicle_state``, ..., :data:`LATER_KEYS`); an agent written for
those sets ``format_obs_keys: later`` in ``agent.yaml`` and the environment says so
(``env.format_obs_keys``). Shapes, dtypes and values are the same under both names.
"""

from __future__ import annotations

import math
from typing import Any

import gym
import numpy as np

LIDAR_RAYS = 300
NEIGHBOURS = 10
WAYPOINT_SHAPE = (4, 20)  # paths, waypoints per path
_BIG = 1e10

# comp-1's StdObs key -> the agent interface option that adds it (None: always there).
_OPTIONS = {
    "dist": None,
    "ego": None,
    "events": None,
    "mission": None,
    "dagm": "drivable_area_grid_map",
    "lidar": "lidar",
    "neighbors": "neighborhood_vehicles",
    "ogm": "ogm",
    "rgb": "rgb",
    "waypoints": "waypoints",
}
# The same keys in later SMARTS releases (``format_obs_keys: later``).
LATER_KEYS = {
    "dist": "distance_travelled",
    "ego": "ego_vehicle_state",
    "events": "events",
    "mission": "mission",
    "dagm": "drivable_area_grid_map",
    "lidar": "lidar_point_cloud",
    "neighbors": "neighborhood_vehicle_states",
    "ogm": "occupancy_grid_map",
    "rgb": "top_down_rgb",
    "waypoints": "waypoint_paths",
}
KEY_SETS = ("comp-1", "later")
_EVENT_NAMES = (
    "agents_alive_done",
    "collisions",
    "not_moving",
    "off_road",
    "off_route",
    "on_shoulder",
    "reached_goal",
    "reached_max_episode_steps",
    "wrong_way",
)


def _box(low, high, shape, dtype) -> gym.spaces.Box:
    return gym.spaces.Box(low=low, high=high, shape=shape, dtype=dtype)


def _ego_space(accelerometer: bool) -> gym.spaces.Dict:
    vector = (3,)
    space = {
        "angular_velocity": _box(-_BIG, _BIG, vector, np.float32),
        "box": _box(0, _BIG, vector, np.float32),
        "heading": _box(-math.pi, math.pi, (), np.float32),
        "lane_index": _box(0, 127, (), np.int8),
        "linear_velocity": _box(-_BIG, _BIG, vector, np.float32),
        "pos": _box(-_BIG, _BIG, vector, np.float64),
        "speed": _box(0, _BIG, (), np.float32),
        "steering": _box(-math.pi, math.pi, (), np.float32),
        "yaw_rate": _box(0, 2 * math.pi, (), np.float32),
    }
    if accelerometer:
        for name in ("angular_acceleration", "angular_jerk", "linear_acceleration", "linear_jerk"):
            space[name] = _box(-_BIG, _BIG, vector, np.float32)
    return gym.spaces.Dict(space)


def _lidar_space(_) -> gym.spaces.Dict:
    rays = (LIDAR_RAYS, 3)
    return gym.spaces.Dict(
        {
            "hit": gym.spaces.MultiBinary(LIDAR_RAYS),
            "point_cloud": _box(-_BIG, _BIG, rays, np.float64),
            "ray_origin": _box(-_BIG, _BIG, rays, np.float64),
            "ray_vector": _box(-_BIG, _BIG, rays, np.float64),
        }
    )


def _neighbours_space(_) -> gym.spaces.Dict:
    n = NEIGHBOURS
    return gym.spaces.Dict(
        {
            "box": _box(0, _BIG, (n, 3), np.float32),
            "heading": _box(-math.pi, math.pi, (n,), np.float32),
            "lane_index": _box(0, 127, (n,), np.int8),
            "pos": _box(-_BIG, _BIG, (n, 3), np.float64),
            "speed": _box(0, _BIG, (n,), np.float32),
        }
    )


def _waypoints_space(_) -> gym.spaces.Dict:
    paths = WAYPOINT_SHAPE
    return gym.spaces.Dict(
        {
            "heading": _box(-math.pi, math.pi, paths, np.float32),
            "lane_index": _box(0, 127, paths, np.int8),
            "lane_width": _box(0, _BIG, paths, np.float32),
            "pos": _box(-_BIG, _BIG, (*paths, 3), np.float64),
            "speed_limit": _box(0, _BIG, paths, np.float32),
        }
    )


def _raster_space(channels: int):
    return lambda setting: _box(0, 255, (setting.height, setting.width, channels), np.uint8)


def get_spaces() -> dict[str, Any]:
    """comp-1's StdObs key -> a function of the interface option's setting giving its space."""
    return {
        "dist": lambda _: _box(0, _BIG, (), np.float32),
        "ego": _ego_space,  # of whether the accelerometer is on
        "events": lambda _: gym.spaces.Dict({e: gym.spaces.Discrete(2) for e in _EVENT_NAMES}),
        "dagm": _raster_space(1),
        "lidar": _lidar_space,
        "mission": lambda _: gym.spaces.Dict({"goal_pos": _box(-_BIG, _BIG, (3,), np.float64)}),
        "neighbors": _neighbours_space,
        "ogm": _raster_space(1),
        "rgb": _raster_space(3),
        "waypoints": _waypoints_space,
    }


def intrfc_to_stdobs(intrfc: str) -> str | None:
    """The comp-1 StdObs key an agent interface option adds (None for options that add none)."""
    return {option: key for key, option in _OPTIONS.items() if option is not None}.get(intrfc)


def _interfaces(env) -> dict[str, Any]:
    """Agent id -> agent interface, as the environment (or a wrapper around it) knows them."""
    interfaces = getattr(env, "agent_interfaces", None)
    if interfaces is None:
        interfaces = {k: spec.interface for k, spec in env.agent_specs.items()}
    return dict(interfaces)


def _key_names(env) -> dict[str, str]:
    """comp-1's key -> the key this environment's agents read (``format_obs_keys``)."""
    chosen = getattr(env, "format_obs_keys", "comp-1")
    if chosen not in KEY_SETS:
        raise ValueError(f"format_obs_keys must be one of {KEY_SETS}, got {chosen!r}")
    return LATER_KEYS if chosen == "later" else {key: key for key in LATER_KEYS}


class FormatObs(gym.ObservationWrapper):
    """SMARTS observations -> ``StdObs`` dicts of numpy arrays. Every agent must have the same
    agent interface (as in SMARTS)."""

    def __init__(self, env) -> None:
        super().__init__(env)
        interfaces = _interfaces(env)
        first = next(iter(interfaces.values()))
        spaces = get_spaces()
        self._accelerometer = bool(getattr(first, "accelerometer", False))
        self._names = _key_names(env)
        self._space = {}
        for key, option in _OPTIONS.items():
            setting = self._accelerometer if key == "ego" else True
            if option is not None:
                setting = getattr(first, option)
                if not setting:
                    continue
                if any(getattr(i, option) != setting for i in interfaces.values()):
                    raise AssertionError(
                        f"To use FormatObs, all agents must have the same AgentInterface.{option}"
                    )
            self._space[self._names[key]] = spaces[key](setting)
        self.observation_space = gym.spaces.Dict(
            {agent_id: gym.spaces.Dict(self._space) for agent_id in interfaces}
        )
        self._keys = [key for key in _OPTIONS if self._names[key] in self._space]

    def observation(self, obs: dict[str, Any]) -> dict[str, dict[str, Any]]:
        return {agent_id: self._format(agent_obs) for agent_id, agent_obs in obs.items()}

    def _format(self, o) -> dict[str, Any]:
        out = {}
        for key in self._keys:
            if key == "ego":
                value = std_ego(o.ego_vehicle_state, self._accelerometer)
            elif key == "mission":
                value = std_mission(o.ego_vehicle_state)
            else:
                field, convert = _CONVERTERS[key]
                value = convert(getattr(o, field))
            out[self._names[key]] = value
        return out


def std_dist(value: float) -> np.float32:
    return np.float32(value)


def std_ego(ego, accelerometer: bool) -> dict[str, Any]:
    out = {
        "angular_velocity": np.asarray(ego.angular_velocity).astype(np.float32),
        "box": np.array(ego.bounding_box.as_lwh, dtype=np.float32),
        "heading": np.float32(ego.heading),
        "lane_index": np.int8(ego.lane_index),
        "linear_velocity": np.asarray(ego.linear_velocity).astype(np.float32),
        "pos": np.asarray(ego.position).astype(np.float64),
        "speed": np.float32(ego.speed),
        "steering": np.float32(ego.steering),
        "yaw_rate": np.float32(ego.yaw_rate) if ego.yaw_rate else np.float32(0),
    }
    if accelerometer:
        for name in ("angular_acceleration", "angular_jerk", "linear_acceleration", "linear_jerk"):
            out[name] = np.asarray(getattr(ego, name)).astype(np.float32)
    return out


def std_events(events) -> dict[str, np.int64]:
    out = {name: np.int64(bool(getattr(events, name))) for name in _EVENT_NAMES}
    out["collisions"] = np.int64(len(events.collisions) > 0)
    return out


def std_mission(ego) -> dict[str, np.ndarray]:
    position = getattr(ego.mission.goal, "position", None)
    if position is None:
        return {"goal_pos": np.zeros(3, np.float64)}
    return {"goal_pos": np.array(position, dtype=np.float64)}


def std_lidar(value) -> dict[str, np.ndarray]:
    points, hits, rays = value
    point_cloud = np.nan_to_num(np.array(points, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    origins, ends = zip(*rays, strict=True)
    out = {
        "hit": np.array(hits, dtype=np.int8),
        "point_cloud": point_cloud,
        "ray_origin": np.array(origins, dtype=np.float64),
        "ray_vector": np.array(ends, dtype=np.float64),
    }
    if any(v.shape[0] != LIDAR_RAYS for v in out.values()):
        raise Exception("Internal Error: Mismatched lidar point cloud shape.")
    return out


def std_neighbors(neighbours) -> dict[str, np.ndarray]:
    n = NEIGHBOURS
    out = {
        "box": np.zeros((n, 3), np.float32),
        "heading": np.zeros(n, np.float32),
        "lane_index": np.zeros(n, np.int8),
        "pos": np.zeros((n, 3), np.float64),
        "speed": np.zeros(n, np.float32),
    }
    for i, v in enumerate(neighbours[:n]):
        out["box"][i] = v.bounding_box.as_lwh
        out["heading"][i] = v.heading
        out["lane_index"][i] = v.lane_index
        out["pos"][i] = v.position
        out["speed"][i] = v.speed
    return out


def std_waypoints(paths) -> dict[str, np.ndarray]:
    """The first 4 paths, each cut to the shortest path's length and to 20 waypoints."""
    rows, cols = WAYPOINT_SHAPE
    out = {
        "heading": np.zeros(WAYPOINT_SHAPE, np.float32),
        "lane_index": np.zeros(WAYPOINT_SHAPE, np.int8),
        "lane_width": np.zeros(WAYPOINT_SHAPE, np.float32),
        "pos": np.zeros((*WAYPOINT_SHAPE, 3), np.float64),
        "speed_limit": np.zeros(WAYPOINT_SHAPE, np.float32),
    }
    length = min(map(len, paths))
    for i, path in enumerate(paths[:rows]):
        for j, w in enumerate(path[: min(length, cols)]):
            out["heading"][i, j] = w.heading
            out["lane_index"][i, j] = w.lane_index
            out["lane_width"][i, j] = w.lane_width
            out["pos"][i, j, :2] = w.pos[:2]
            out["speed_limit"][i, j] = w.speed_limit
    return out


def std_raster(value) -> np.ndarray:
    return value.data.astype(np.uint8)


# StdObs key -> (the Observation field it comes from, its converter).
_CONVERTERS = {
    "dist": ("distance_travelled", std_dist),
    "events": ("events", std_events),
    "lidar": ("lidar_point_cloud", std_lidar),
    "neighbors": ("neighborhood_vehicle_states", std_neighbors),
    "waypoints": ("waypoint_paths", std_waypoints),
    "dagm": ("drivable_area_grid_map", std_raster),
    "ogm": ("occupancy_grid_map", std_raster),
    "rgb": ("top_down_rgb", std_raster),
}
