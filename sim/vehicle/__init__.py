"""Mission vehicles: kinematic model, limits and the action spaces that drive them."""

from sim.vehicle.actions import (
    DECODERS,
    MAX_ACTION_MAGNITUDE,
    ControlContext,
    InvalidAction,
    check_action,
    parse_action,
)
from sim.vehicle.bicycle import Pose, bicycle_step
from sim.vehicle.limits import LIMITS, VehicleLimits

__all__ = [
    "DECODERS",
    "LIMITS",
    "MAX_ACTION_MAGNITUDE",
    "ControlContext",
    "InvalidAction",
    "Pose",
    "VehicleLimits",
    "bicycle_step",
    "check_action",
    "parse_action",
]
