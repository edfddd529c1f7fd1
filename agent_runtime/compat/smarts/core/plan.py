"""SMARTS's mission types (``smarts.core.plan``): where an agent starts and where it must go."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from smarts.core.coordinates import Dimensions, Heading, Point


class PlanningError(Exception):
    """SMARTS's error for a route it cannot plan on the map."""


@dataclass(frozen=True)
class VehicleSpec:
    veh_id: str
    veh_config_type: str
    dimensions: Dimensions


@dataclass(frozen=True)
class Start:
    position: np.ndarray  # (2,) [m]
    heading: Heading
    from_front_bumper: bool = True


class Goal:
    def is_endless(self) -> bool:
        return True

    def is_reached(self, vehicle) -> bool:
        return False


@dataclass(frozen=True)
class EndlessGoal(Goal):
    pass


@dataclass(frozen=True)
class PositionalGoal(Goal):
    position: Point  # [m]
    radius: float  # [m]

    def is_endless(self) -> bool:
        return False

    def is_reached(self, vehicle) -> bool:
        """Whether ``vehicle`` (anything with a ``position``) is within ``radius``."""
        x, y = vehicle.position[0], vehicle.position[1]
        return bool(np.hypot(x - self.position.x, y - self.position.y) <= self.radius)


class Via(NamedTuple):
    road_id: str
    lane_index: int
    lane_offset: float
    required_speed: float


@dataclass(frozen=True)
class Mission:
    start: Start
    goal: Goal
    route_vias: tuple[str, ...] = ()  # road ids the route passes, in order
    start_time: float = 0.0  # [s]
    entry_tactic: object = None
    via: tuple[Via, ...] = ()
    vehicle_spec: object = None
    route: tuple[str, ...] = field(default=(), compare=False)  # ours: every road of the route

    @property
    def has_fixed_route(self) -> bool:
        return not self.goal.is_endless()

    def is_endless(self) -> bool:
        return self.goal.is_endless()

    def is_complete(self, vehicle, distance_travelled: float) -> bool:
        return self.goal.is_reached(vehicle)
