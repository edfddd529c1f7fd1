"""Physical limits of mission vehicles, shared by every action space."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleLimits:
    max_speed: float = 28.0  # [m/s]; also bounds TargetPose displacement (2.8 m per 0.1 s step)
    max_acceleration: float = 3.0  # [m/s^2] at full throttle
    max_deceleration: float = 8.0  # [m/s^2] at full brake
    max_steering: float = 0.6  # [rad] front wheel angle at steering = +-1
    max_lane_speed: float = 28.0  # [m/s] target speed bound of LaneWithContinuousSpeed


LIMITS = VehicleLimits()
