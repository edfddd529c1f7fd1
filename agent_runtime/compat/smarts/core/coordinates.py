"""SMARTS's coordinate types (``smarts.core.coordinates``): ``Heading`` (0 = north,
counter-clockwise, radians in [-pi, pi]), ``Dimensions``, ``Point``, ``RefLinePoint``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from smarts.core.utils.math import (
    fast_quaternion_from_angle,
    radians_to_vec,
    yaw_from_quaternion,
)


class Heading(float):
    """A heading [rad]: 0 faces north (+y), counter-clockwise, kept in [-pi, pi]."""

    def __new__(cls, value: float = 0.0) -> Heading:
        value = float(value) % (2 * math.pi)
        if value > math.pi:
            value -= 2 * math.pi
        return float.__new__(cls, value)

    def __repr__(self) -> str:
        return f"Heading({float(self)!r})"

    @classmethod
    def from_bullet(cls, bullet_heading: float) -> Heading:
        """Bullet's heading is already SMARTS's."""
        return cls(bullet_heading)

    @classmethod
    def from_panda3d(cls, p3d_heading: float) -> Heading:
        """Panda3D: degrees, 0 north, counter-clockwise."""
        return cls(math.radians(p3d_heading))

    @classmethod
    def from_sumo(cls, sumo_heading: float) -> Heading:
        """SUMO: degrees, 0 north, clockwise."""
        return cls(_flip_clockwise(math.radians(sumo_heading)))

    @property
    def as_panda3d(self) -> float:
        return math.degrees(self)

    @property
    def as_bullet(self) -> Heading:
        return self

    @property
    def as_sumo(self) -> float:
        return math.degrees(_flip_clockwise(self))

    def relative_to(self, other: float) -> Heading:
        """This heading less ``other``, wrapped into [-pi, pi]."""
        return Heading(self - other)

    def direction_vector(self) -> np.ndarray:
        """The unit vector (2,) this heading points along."""
        return radians_to_vec(self)


def _flip_clockwise(x: float) -> float:
    return (2 * math.pi - x) % (2 * math.pi)


class Point(NamedTuple):
    x: float
    y: float
    z: float = 0.0

    def as_np_array(self) -> np.ndarray:
        return np.array(self)


class RefLinePoint(NamedTuple):
    """A position along a lane's reference line: ``s`` [m] along it, ``t`` [m] to its left,
    ``h`` [m] above it."""

    s: float
    t: float = 0.0
    h: float = 0.0


@dataclass(frozen=True)
class Dimensions:
    """A bounding box's length, width and height [m]."""

    length: float
    width: float
    height: float

    @classmethod
    def init_with_defaults(cls, length, width, height, defaults: Dimensions) -> Dimensions:
        return cls(
            length if length else defaults.length,
            width if width else defaults.width,
            height if height else defaults.height,
        )

    @classmethod
    def copy_with_defaults(cls, dims: Dimensions | None, defaults: Dimensions) -> Dimensions:
        if dims is None:
            return defaults
        return cls.init_with_defaults(dims.length, dims.width, dims.height, defaults)

    @property
    def as_lwh(self) -> tuple[float, float, float]:
        return (self.length, self.width, self.height)

    def equal_if_defined(self, length: float, width: float, height: float) -> bool:
        return (
            (not self.length or self.length == length)
            and (not self.width or self.width == width)
            and (not self.height or self.height == height)
        )


# SMARTS's earlier name for the same box.
BoundingBox = Dimensions


@dataclass
class Pose:
    """A position (3,) [m] and heading; SMARTS's orientation quaternion is derived."""

    position: np.ndarray
    orientation: np.ndarray
    heading_: Heading | None = None

    @classmethod
    def from_center(cls, base_position, heading: float) -> Pose:
        heading = Heading(heading)
        position = np.array([*base_position, 0][:3], dtype=float)
        return cls(position, fast_quaternion_from_angle(heading), heading)

    @property
    def heading(self) -> Heading:
        if self.heading_ is None:
            self.heading_ = Heading(yaw_from_quaternion(self.orientation))
        return self.heading_
