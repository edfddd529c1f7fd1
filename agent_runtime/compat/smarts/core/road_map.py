"""SMARTS's road map ``Waypoint`` (``smarts.core.road_map``): a point on a lane's centre line."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from smarts.core.coordinates import Heading
from smarts.core.utils.math import signed_dist_to_line, vec_2d


@dataclass(frozen=True)
class Waypoint:
    pos: np.ndarray  # (2,) [m] on the lane's centre line
    heading: Heading  # [rad] of the lane here (0 = north)
    lane_id: str
    lane_width: float  # [m]
    speed_limit: float  # [m/s]
    lane_index: int  # 0 = the rightmost lane
    lane_offset: float = 0.0  # [m] along the lane

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Waypoint):
            return False
        return (
            (self.pos == other.pos).all()
            and self.heading == other.heading
            and self.lane_width == other.lane_width
            and self.speed_limit == other.speed_limit
            and self.lane_id == other.lane_id
            and self.lane_index == other.lane_index
        )

    def __hash__(self) -> int:
        return hash(
            (
                *self.pos,
                self.heading,
                self.lane_width,
                self.speed_limit,
                self.lane_id,
                self.lane_index,
            )
        )

    def relative_heading(self, h: float) -> Heading:
        """How far the lane here turns from ``h``: ``h`` less this waypoint's heading."""
        if not isinstance(h, Heading):
            h = Heading(h)
        return h.relative_to(self.heading)

    def signed_lateral_error(self, p) -> float:
        """Distance [m] from ``p`` to the lane's direction line here, positive to its left."""
        return signed_dist_to_line(p, self.pos, self.heading.direction_vector())

    def dist_to(self, p) -> float:
        """Distance [m] from ``p`` (2 or 3 components) to this waypoint."""
        return float(np.linalg.norm(self.pos - vec_2d(p)))


def make_waypoint(pos, heading, lane_id, lane_width, speed_limit, lane_index, lane_offset):
    """A :class:`Waypoint` without the frozen dataclass's per-field checks: a step's
    observation holds a few hundred."""
    waypoint = object.__new__(Waypoint)
    fields = waypoint.__dict__
    fields["pos"] = pos
    fields["heading"] = heading
    fields["lane_id"] = lane_id
    fields["lane_width"] = lane_width
    fields["speed_limit"] = speed_limit
    fields["lane_index"] = lane_index
    fields["lane_offset"] = lane_offset
    return waypoint
