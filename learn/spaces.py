"""Gymnasium spaces of the agent interface; :mod:`learn.encoding` encodes observations into
them."""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from learn.encoding import (
    DEFAULT_MAX_NEIGHBOURS,
    EGO_FIELDS,
    EVENT_NAMES,
    RASTER_NAMES,
    WAYPOINT_FIELDS,
    encode,
)
from sim.interface import ActionSpace, AgentInterface
from sim.vehicle.limits import LIMITS

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
    """One agent's simulator observation as a member of :func:`observation_space`."""
    rasters = tuple(name for name in RASTER_NAMES if getattr(interface, name))
    return encode(
        obs, interface.max_waypoint_paths, interface.waypoints_per_path, max_neighbours, rasters
    )


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
