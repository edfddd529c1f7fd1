"""Gymnasium spaces of the agent interface, and the observation dict encoded into them.

The simulator's observation (``shared/spec/agent-interface.md``) has variable-length lists
(neighbours, waypoints) and strings (road and lane ids); a space needs fixed shapes. The encoding
keeps every numeric field under its interface name, pads lists to fixed sizes with a ``mask``, and
leaves out the ids (they are in ``info`` when a user needs them). Rasters pass through unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from sim.interface import ActionSpace, AgentInterface
from sim.vehicle.limits import LIMITS

EVENT_NAMES = (
    "collisions",
    "off_road",
    "off_route",
    "on_shoulder",
    "wrong_way",
    "not_moving",
    "reached_goal",
    "reached_max_episode_steps",
)
# (name, length) of the ego vectors; scalars have length 0 (shape ()).
EGO_FIELDS = (
    ("position", 3),
    ("heading", 0),
    ("speed", 0),
    ("bounding_box", 3),
    ("steering", 0),
    ("yaw_rate", 0),
    ("lane_position", 2),
    ("linear_velocity", 3),
    ("angular_velocity", 3),
    ("linear_acceleration", 3),
    ("angular_acceleration", 3),
    ("linear_jerk", 3),
    ("angular_jerk", 3),
)
WAYPOINT_FIELDS = ("heading", "lane_width", "speed_limit", "lane_offset")
DEFAULT_MAX_NEIGHBOURS = 16
_INF = np.inf


def _box(shape: tuple[int, ...], low: float = -_INF, high: float = _INF) -> spaces.Box:
    return spaces.Box(low, high, shape, np.float32)


def _flag() -> spaces.Box:
    # A 0/1 value as a uint8 scalar box: Discrete/MultiBinary would break vectorised batching of
    # the nested dict in some training libraries, a Box never does.
    return spaces.Box(0, 1, (), np.uint8)


def observation_space(
    interface: AgentInterface, max_neighbours: int = DEFAULT_MAX_NEIGHBOURS
) -> spaces.Dict:
    """The space of :func:`encode_observation`'s output for this interface."""
    n, p, w = max_neighbours, interface.max_waypoint_paths, interface.waypoints_per_path
    ego = {name: _box((size,) if size else ()) for name, size in EGO_FIELDS}
    ego["lane_index"] = spaces.Box(0, 255, (), np.int32)
    ego["goal_position"] = _box((2,))
    ego["goal_radius"] = _box((), 0.0)
    out = {
        "dt": _box((), 0.0),
        "step_count": spaces.Box(0, np.iinfo(np.int32).max, (), np.int32),
        "elapsed_sim_time": _box((), 0.0),
        "distance_travelled": _box((), 0.0),
        "events": spaces.Dict({name: _flag() for name in EVENT_NAMES}),
        "ego_vehicle_state": spaces.Dict(ego),
        "neighborhood_vehicle_states": spaces.Dict(
            {
                "mask": spaces.Box(0, 1, (n,), np.uint8),
                "position": _box((n, 3)),
                "heading": _box((n,)),
                "speed": _box((n,)),
                "bounding_box": _box((n, 3), 0.0),
                "lane_index": spaces.Box(0, 255, (n,), np.int32),
            }
        ),
        "waypoint_paths": spaces.Dict(
            {
                "mask": spaces.Box(0, 1, (p, w), np.uint8),
                "pos": _box((p, w, 2)),
                "lane_index": spaces.Box(0, 255, (p, w), np.int32),
                **{name: _box((p, w)) for name in WAYPOINT_FIELDS},
            }
        ),
    }
    px = interface.img_pixels
    if interface.drivable_area_grid_map:
        out["drivable_area_grid_map"] = spaces.Box(0, 255, (px, px), np.uint8)
    if interface.occupancy_grid_map:
        out["occupancy_grid_map"] = spaces.Box(0, 255, (px, px), np.uint8)
    if interface.top_down_rgb:
        out["top_down_rgb"] = spaces.Box(0, 255, (px, px, 3), np.uint8)
    return spaces.Dict(out)


def encode_observation(
    obs: dict, interface: AgentInterface, max_neighbours: int = DEFAULT_MAX_NEIGHBOURS
) -> dict:
    """One agent's simulator observation as a member of :func:`observation_space`. The nearest
    ``max_neighbours`` neighbours are kept (the simulator lists them nearest first)."""
    f32 = np.float32
    ego_in = obs["ego_vehicle_state"]
    ego = {name: np.asarray(ego_in[name], f32) for name, _ in EGO_FIELDS}
    ego["lane_index"] = np.asarray(ego_in["lane_index"], np.int32)
    goal = ego_in["mission"]["goal"]
    ego["goal_position"] = np.asarray(goal["position"], f32)
    ego["goal_radius"] = np.asarray(goal["radius"], f32)

    n = max_neighbours
    others = obs["neighborhood_vehicle_states"][:n]
    k = len(others)
    nbr = {
        "mask": np.zeros(n, np.uint8),
        "position": np.zeros((n, 3), f32),
        "heading": np.zeros(n, f32),
        "speed": np.zeros(n, f32),
        "bounding_box": np.zeros((n, 3), f32),
        "lane_index": np.zeros(n, np.int32),
    }
    if k:
        nbr["mask"][:k] = 1
        nbr["position"][:k] = [o["position"] for o in others]
        nbr["heading"][:k] = [o["heading"] for o in others]
        nbr["speed"][:k] = [o["speed"] for o in others]
        nbr["bounding_box"][:k] = [o["bounding_box"] for o in others]
        nbr["lane_index"][:k] = [o["lane_index"] for o in others]

    p, w = interface.max_waypoint_paths, interface.waypoints_per_path
    paths = {
        "mask": np.zeros((p, w), np.uint8),
        "pos": np.zeros((p, w, 2), f32),
        "lane_index": np.zeros((p, w), np.int32),
        **{name: np.zeros((p, w), f32) for name in WAYPOINT_FIELDS},
    }
    for i, path in enumerate(obs["waypoint_paths"][:p]):
        m = min(len(path), w)
        if not m:
            continue
        path = path[:m]
        paths["mask"][i, :m] = 1
        paths["pos"][i, :m] = [wp["pos"] for wp in path]
        paths["lane_index"][i, :m] = [wp["lane_index"] for wp in path]
        for name in WAYPOINT_FIELDS:
            paths[name][i, :m] = [wp[name] for wp in path]

    events = obs["events"]
    out = {
        "dt": np.asarray(obs["dt"], f32),
        "step_count": np.asarray(obs["step_count"], np.int32),
        "elapsed_sim_time": np.asarray(obs["elapsed_sim_time"], f32),
        "distance_travelled": np.asarray(obs["distance_travelled"], f32),
        "events": {name: np.asarray(bool(events[name]), np.uint8) for name in EVENT_NAMES},
        "ego_vehicle_state": ego,
        "neighborhood_vehicle_states": nbr,
        "waypoint_paths": paths,
    }
    for name in ("drivable_area_grid_map", "occupancy_grid_map", "top_down_rgb"):
        if name in obs:
            out[name] = obs[name]
    return out


def action_space(space: ActionSpace) -> spaces.Box:
    """The Box of one action space, bounded where the simulator clips (``sim/vehicle``)."""
    reach = LIMITS.max_speed * 0.5  # [m] a generous bound on one step's displacement
    bounds = {
        # [x, y, heading, dt]: a map-sized box; the simulator caps the displacement per step.
        ActionSpace.TargetPose: ([-1e5, -1e5, -math.pi, 0.0], [1e5, 1e5, math.pi, 1.0]),
        ActionSpace.RelativeTargetPose: ([-reach, -reach, -math.pi], [reach, reach, math.pi]),
        ActionSpace.Continuous: ([0.0, 0.0, -1.0], [1.0, 1.0, 1.0]),
        ActionSpace.LaneWithContinuousSpeed: ([0.0, -1.0], [LIMITS.max_lane_speed, 1.0]),
    }[space]
    low, high = (np.asarray(b, np.float32) for b in bounds)
    return spaces.Box(low, high, dtype=np.float32)
