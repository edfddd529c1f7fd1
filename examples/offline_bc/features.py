"""Fixed-size arrays for offline learning from our observation dicts and recorded poses.

Observation vector, float32, shape (OBS_SIZE,) = 7 ego features + NEIGHBOURS x 7:

- ego: speed [m/s], steering [rad], yaw rate [rad/s], lateral offset from the lane centre [m,
  left +], goal ahead / left of the ego [m] (ego frame), distance to the goal [m];
- the NEIGHBOURS nearest other vehicles (nearest first; zero rows when fewer): present (1/0),
  ahead / left [m] (ego frame), heading relative to the ego [rad, wrapped], speed [m/s],
  length [m], width [m].

Action, float32, shape (3,): the next pose relative to the current one, in the current ego frame:
forward [m], left [m], heading change [rad] over one 0.1 s step. :func:`to_target_pose` turns it
back into our ``TargetPose`` action ``[x, y, heading, dt]``.
"""

from __future__ import annotations

import math

import numpy as np

NEIGHBOURS = 8
EGO_FEATURES = 7
NEIGHBOUR_FEATURES = 7
OBS_SIZE = EGO_FEATURES + NEIGHBOURS * NEIGHBOUR_FEATURES
ACTION_SIZE = 3
# Reward (until the Gymnasium env's default reward lands on main, which this should then call):
# progress towards the goal [m] per step, +GOAL_BONUS on arrival, -CRASH_PENALTY on a collision or
# leaving the road.
GOAL_BONUS = 10.0
CRASH_PENALTY = 10.0


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _ego_frame(dx: float, dy: float, heading: float) -> tuple[float, float]:
    c, s = math.cos(heading), math.sin(heading)
    return c * dx + s * dy, -s * dx + c * dy


def ego_pose(obs: dict) -> tuple[float, float, float]:
    ego = obs["ego_vehicle_state"]
    return float(ego["position"][0]), float(ego["position"][1]), float(ego["heading"])


def goal_distance(obs: dict) -> float:
    x, y, _ = ego_pose(obs)
    gx, gy = obs["ego_vehicle_state"]["mission"]["goal"]["position"]
    return math.hypot(gx - x, gy - y)


def observation_vector(obs: dict) -> np.ndarray:
    ego = obs["ego_vehicle_state"]
    x, y, h = ego_pose(obs)
    gx, gy = ego["mission"]["goal"]["position"]
    ahead, left = _ego_frame(gx - x, gy - y, h)
    out = np.zeros(OBS_SIZE, dtype=np.float32)
    out[:EGO_FEATURES] = (
        ego["speed"],
        ego["steering"],
        ego["yaw_rate"],
        ego["lane_position"][1],
        ahead,
        left,
        math.hypot(ahead, left),
    )
    for k, other in enumerate(obs["neighborhood_vehicle_states"][:NEIGHBOURS]):
        ox, oy = other["position"][0], other["position"][1]
        o_ahead, o_left = _ego_frame(ox - x, oy - y, h)
        row = EGO_FEATURES + k * NEIGHBOUR_FEATURES
        out[row : row + NEIGHBOUR_FEATURES] = (
            1.0,
            o_ahead,
            o_left,
            _wrap(other["heading"] - h),
            other["speed"],
            other["bounding_box"][0],
            other["bounding_box"][1],
        )
    return out


def pose_action(pose: tuple[float, float, float], target: tuple[float, float, float]) -> np.ndarray:
    """The action that moves from ``pose`` to ``target`` (x [m], y [m], heading [rad])."""
    forward, left = _ego_frame(target[0] - pose[0], target[1] - pose[1], pose[2])
    return np.array([forward, left, _wrap(target[2] - pose[2])], dtype=np.float32)


def to_target_pose(
    pose: tuple[float, float, float], action: np.ndarray, dt: float = 0.1
) -> list[float]:
    """Our ``TargetPose`` action ``[x, y, heading, dt]`` for a dataset action taken at ``pose``."""
    x, y, h = pose
    forward, left, turn = (float(a) for a in action)
    c, s = math.cos(h), math.sin(h)
    return [x + c * forward - s * left, y + s * forward + c * left, _wrap(h + turn), dt]


def step_reward(before: dict, after: dict) -> float:
    events = after["events"]
    reward = goal_distance(before) - goal_distance(after)
    if events.get("reached_goal"):
        reward += GOAL_BONUS
    if events.get("collisions") or events.get("off_road"):
        reward -= CRASH_PENALTY
    return float(reward)
