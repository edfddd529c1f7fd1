"""Per-step events of a mission vehicle, from our own geometry (not SUMO's)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from sim.compiled import compiled
from sim.geometry import box_overlaps_box
from sim.road import LanePosition, angle_between
from sim.vehicle.states import VehicleStates

_boxes = compiled("sim._boxes")

WRONG_WAY_ANGLE = math.pi / 2  # [rad] heading difference to the lane beyond which is wrong way
NOT_MOVING_SPEED = 0.1  # [m/s]
NOT_MOVING_STEPS = 60  # 6 s at dt = 0.1 s


class Events(NamedTuple):  # immutable, and cheaper to make per step than a frozen dataclass
    collisions: tuple[str, ...]  # ids of the vehicles the ego's box overlapped
    off_road: bool
    off_route: bool
    on_shoulder: bool
    wrong_way: bool
    not_moving: bool
    reached_goal: bool
    reached_max_episode_steps: bool

    def as_observation(self) -> dict:
        return {
            "collisions": list(self.collisions),
            "off_road": self.off_road,
            "off_route": self.off_route,
            "on_shoulder": self.on_shoulder,
            "wrong_way": self.wrong_way,
            "not_moving": self.not_moving,
            "reached_goal": self.reached_goal,
            "reached_max_episode_steps": self.reached_max_episode_steps,
        }


def collisions(
    x: float,
    y: float,
    heading: float,
    length: float,
    width: float,
    others: VehicleStates,
    distance: np.ndarray | None = None,
) -> tuple[str, ...]:
    """Ids of ``others`` whose oriented box overlaps the ego's (sorted). ``distance``: the
    centres' distances from (x, y) [m] when the caller has them already."""
    if not len(others):
        return ()
    if distance is None:
        distance = np.hypot(others.x - x, others.y - y)
    if _boxes is not None:
        hit = _boxes.overlapping(x, y, heading, length, width, others.values, distance)
        return tuple(sorted([others.ids[i] for i in hit]))
    # Boxes further apart than their half-diagonals cannot touch: skip the exact test for them.
    # (In place, the same operations as 0.5 * (hypot + np.hypot(...)), with fewer arrays.)
    values = others.values
    reach = np.hypot(values[:, 4], values[:, 5])  # length, width
    reach += math.hypot(length, width)
    reach *= 0.5
    near = (distance <= reach).nonzero()[0]
    if not len(near):
        return ()
    ego = (x, y, heading, length, width)
    hit = []
    # Each candidate's row as plain floats in one call (x, y, heading, speed, length, width).
    for i, (bx, by, bh, _, bl, bw) in zip(
        near.tolist(), values.take(near, 0).tolist(), strict=True
    ):
        if box_overlaps_box(ego, (bx, by, bh, bl, bw)):
            hit.append(others.ids[i])
    return tuple(sorted(hit))


def is_wrong_way(heading: float, lane: LanePosition, in_junction: bool) -> bool:
    """Heading more than 90 degrees from the lane's direction, outside junctions."""
    return not in_junction and angle_between(heading, lane.heading) > WRONG_WAY_ANGLE


def reached_goal(x: float, y: float, goal: tuple[float, float], radius: float) -> bool:
    return math.hypot(x - goal[0], y - goal[1]) <= radius
