"""Kinematic bicycle model (centre-of-gravity reference, no tyre slip)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Pose:
    """Where a mission vehicle is after a step: centre (x, y) [m], heading [rad], speed [m/s],
    front wheel angle ``steering`` [rad]."""

    x: float
    y: float
    heading: float
    speed: float
    steering: float = 0.0


def wheelbase(length: float) -> float:
    """Axle distance [m] of a vehicle of ``length`` [m] (typical passenger car proportion)."""
    return 0.6 * length


def bicycle_step(
    pose: Pose, acceleration: float, steering: float, dt: float, length: float, max_speed: float
) -> Pose:
    """Advance ``pose`` by ``dt`` [s] under ``acceleration`` [m/s^2] and front wheel angle
    ``steering`` [rad]. Speed stays within [0, max_speed]; the vehicle never reverses."""
    lr = wheelbase(length) / 2
    beta = math.atan(0.5 * math.tan(steering))
    speed = min(max(pose.speed + acceleration * dt, 0.0), max_speed)
    mean_speed = 0.5 * (pose.speed + speed)
    heading = pose.heading + mean_speed / lr * math.sin(beta) * dt
    direction = pose.heading + beta
    x = pose.x + mean_speed * math.cos(direction) * dt
    y = pose.y + mean_speed * math.sin(direction) * dt
    return Pose(x, y, math.remainder(heading, 2 * math.pi), speed, steering)
