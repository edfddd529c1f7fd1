"""Mission vehicles: kinematic model, limits and the action spaces that drive them."""

from sim.vehicle.actions import DECODERS, ControlContext, parse_action
from sim.vehicle.bicycle import Pose, bicycle_step
from sim.vehicle.limits import LIMITS, VehicleLimits

__all__ = [
    "DECODERS",
    "LIMITS",
    "ControlContext",
    "Pose",
    "VehicleLimits",
    "bicycle_step",
    "parse_action",
]
