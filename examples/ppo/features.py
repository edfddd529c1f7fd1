"""What the PPO baseline sees and how its four actions drive (numpy only: runs in the sandbox).

Like the Driving SMARTS 2022 baseline: the BEV image plus the distance and heading error to the
goal, and a small discrete action set (brake, forward, turn left, turn right) mapped onto
LaneWithContinuousSpeed. Works on the arrays observation (``observation_format: arrays``), which
the training environment and the sandbox both give, so both compute the very same inputs.
"""

from __future__ import annotations

import math

import numpy as np

IMG_PIXELS = 64
VECTOR_SIZE = 4
N_ACTIONS = 4  # brake, forward, left, right
CRUISE_SPEED = 12.0  # [m/s] the most "forward" asks for
SPEED_STEP = 2.0  # [m/s] "forward" asks for this much more than the current speed


def features(encoded: dict) -> dict[str, np.ndarray]:
    """``image``: (3, 64, 64) uint8 top_down_rgb, channel first; ``vector``: distance to the goal
    [100 m], sine and cosine of the heading error to the goal, speed [20 m/s]."""
    ego = encoded["ego_vehicle_state"]
    dx, dy = ego["goal_position"] - ego["position"][:2]
    error = math.atan2(dy, dx) - float(ego["heading"][0])
    vector = np.array(
        [
            min(math.hypot(dx, dy) / 100.0, 5.0),
            math.sin(error),
            math.cos(error),
            float(ego["speed"][0]) / 20.0,
        ],
        np.float32,
    )
    image = np.ascontiguousarray(np.transpose(encoded["top_down_rgb"], (2, 0, 1)))
    return {"image": image, "vector": vector}


def to_action(choice: int, speed: float) -> list[float]:
    """A LaneWithContinuousSpeed action [target speed m/s, lane change] for ``choice``."""
    if choice == 0:  # brake
        return [0.0, 0.0]
    if choice == 1:  # forward
        return [min(speed + SPEED_STEP, CRUISE_SPEED), 0.0]
    keep = max(speed, 3.0)
    return [keep, 1.0] if choice == 2 else [keep, -1.0]  # left, right
