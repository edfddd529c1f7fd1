"""The agent-interface observation encoded into fixed-shape numpy arrays (the Gymnasium space).

The simulator's observation (``docs/agent-interface.md``) has variable-length lists
(neighbours, waypoints) and strings (road and lane ids); a space needs fixed shapes. The encoding
keeps every numeric field under its interface name, pads lists to fixed sizes with a ``mask``, and
leaves out the ids. Rasters pass through unchanged.

numpy only and no import of this project: a submission copies this file next to its
``policy.py`` to encode, in the sandbox, the observations it was trained on.
"""

from __future__ import annotations

import numpy as np

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
RASTER_NAMES = ("drivable_area_grid_map", "occupancy_grid_map", "top_down_rgb")


def encode(
    obs: dict,
    max_paths: int = 4,
    waypoints: int = 50,
    max_neighbours: int = DEFAULT_MAX_NEIGHBOURS,
    rasters: tuple[str, ...] = RASTER_NAMES,
) -> dict:
    """One agent's observation (the agent-interface dict) as fixed-shape numpy arrays: the member
    of ``learn.spaces.observation_space`` for an interface with ``max_waypoint_paths=max_paths``
    and ``waypoints_per_path=waypoints``. The nearest ``max_neighbours`` neighbours are kept (the
    simulator lists them nearest first). Of the rasters, those named in ``rasters`` pass through
    when present."""
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

    p, w = max_paths, waypoints
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
    for name in rasters:
        if name in obs:
            out[name] = obs[name]
    return out
