"""The four action spaces of the agent interface: validation and decoding into the next pose.

Each decoder takes a validated, clipped action and the vehicle's current pose and returns the
pose after one step. Values beyond a space's physical range are clipped; a wrong shape, a
non-finite value or a magnitude past :data:`MAX_ACTION_MAGNITUDE` is an invalid action
(:func:`check_action` raises :class:`InvalidAction` naming the rule and the value).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from arena.errors import ParticipantError
from sim.geometry import wrap
from sim.interface import ACTION_LENGTH, ActionSpace
from sim.road.waypoints import preferred_successor
from sim.vehicle.bicycle import Pose, bicycle_step, wheelbase
from sim.vehicle.limits import LIMITS

if TYPE_CHECKING:
    from sim.road import LanePosition, RoadNetwork


@dataclass
class ControlContext:
    """What decoders may need besides the action: the step, the vehicle and the road."""

    dt: float  # [s]
    length: float  # [m] vehicle length
    road: RoadNetwork
    route: tuple[str, ...]
    # LaneWithContinuousSpeed keeps the lane it is steering to between steps.
    target_lane: str | None = None
    # The road's nearest_lane of the vehicle's pose, when the caller has it already.
    lane: LanePosition | None = None


# Bound on every action element. Finite but huge values (1e300) overflow the geometry (hypot ->
# inf, inf/inf -> NaN) and would reach SUMO as a NaN position, i.e. a simulator error the
# participant is not charged for: they are the agent's invalid action instead. No map is larger
# than this [m], and no sane heading, speed or control value comes near it.
MAX_ACTION_MAGNITUDE = 1.0e6
# How much of an offending value a message quotes.
_QUOTE_CHARS = 80


class InvalidAction(ParticipantError, ValueError):
    """An action broke a rule; ``rule`` is its short name, the message quotes the value."""

    def __init__(self, rule: str, message: str) -> None:
        super().__init__(f"{message} [rule: {rule}]")
        self.rule = rule


def quote(value: object) -> str:
    """``repr`` cut short: an agent's value may be arbitrarily large."""
    text = repr(value)
    return text if len(text) <= _QUOTE_CHARS else text[: _QUOTE_CHARS - 3] + "..."


def check_action(raw: object, space: ActionSpace) -> np.ndarray:
    """The action as a float array of the space's length; :class:`InvalidAction` otherwise."""
    length = ACTION_LENGTH[space]
    # The usual action, in-range floats in a list or a float array, passes every check below:
    # test it in plain Python, without numpy's per-call overhead. Anything else (NaN, inf,
    # ints, other shapes) takes the full path and its messages.
    values = None
    if type(raw) in (list, tuple):
        values = raw
    elif type(raw) is np.ndarray and raw.dtype.kind == "f" and raw.shape == (length,):
        values = raw.tolist()
    if values is not None and len(values) == length:
        for value in values:
            if (
                type(value) is not float
                or not -MAX_ACTION_MAGNITUDE <= value <= MAX_ACTION_MAGNITUDE
            ):
                break
        else:
            return np.asarray(raw, dtype=np.float64)
    try:
        arr = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as error:
        # OverflowError: a JSON integer beyond float range (10**400) is not a number we can use.
        raise InvalidAction(
            "not-numbers", f"{space} action {quote(raw)} is not {length} numbers ({error})"
        ) from None
    if arr.shape != (length,):
        raise InvalidAction(
            "shape", f"{space} action {quote(raw)} has shape {arr.shape}, expected ({length},)"
        )
    if not np.isfinite(arr).all():
        raise InvalidAction("finite", f"{space} action {quote(raw)} holds NaN or infinity")
    if (np.abs(arr) > MAX_ACTION_MAGNITUDE).any():
        raise InvalidAction(
            "range",
            f"{space} action {quote(raw)} has a value beyond +-{MAX_ACTION_MAGNITUDE:g}",
        )
    return arr


def parse_action(raw: object, space: ActionSpace) -> np.ndarray | None:
    """The action as a float array of the space's length, or None when it is invalid."""
    try:
        return check_action(raw, space)
    except InvalidAction:
        return None


def _limit_displacement(pose: Pose, x: float, y: float, heading: float, dt: float) -> Pose:
    dx, dy = x - pose.x, y - pose.y
    dist = math.hypot(dx, dy)
    max_dist = LIMITS.max_speed * dt
    if dist > max_dist:
        dx, dy, dist = dx * max_dist / dist, dy * max_dist / dist, max_dist
    return Pose(pose.x + dx, pose.y + dy, wrap(heading), dist / dt, 0.0)


def target_pose(action: np.ndarray, pose: Pose, ctx: ControlContext) -> Pose:
    """[x, y, heading, dt]: move to the pose over one step (``dt`` element is not used: a step
    is always ``ctx.dt``); displacement capped at max_speed x dt."""
    x, y, heading = action[:3].tolist()  # plain floats: cheaper scalar maths, same values
    return _limit_displacement(pose, x, y, heading, ctx.dt)


def relative_target_pose(action: np.ndarray, pose: Pose, ctx: ControlContext) -> Pose:
    """[dx, dy, dheading] in the ego frame (x forward, y left); same displacement cap."""
    forward, left, turn = action.tolist()  # plain floats: cheaper scalar maths, same values
    c, s = math.cos(pose.heading), math.sin(pose.heading)
    x = pose.x + c * forward - s * left
    y = pose.y + s * forward + c * left
    return _limit_displacement(pose, x, y, pose.heading + turn, ctx.dt)


def continuous(action: np.ndarray, pose: Pose, ctx: ControlContext) -> Pose:
    """[throttle 0..1, brake 0..1, steering -1..1] through the kinematic bicycle model."""
    throttle, brake, steer = np.clip(action, [0.0, 0.0, -1.0], [1.0, 1.0, 1.0]).tolist()
    acceleration = throttle * LIMITS.max_acceleration - brake * LIMITS.max_deceleration
    return bicycle_step(
        pose, acceleration, steer * LIMITS.max_steering, ctx.dt, ctx.length, LIMITS.max_speed
    )


def lane_with_continuous_speed(action: np.ndarray, pose: Pose, ctx: ControlContext) -> Pose:
    """[target_speed m/s, lane_change -1|0|+1]: a built-in controller tracks the target speed and
    the centreline of the target lane (+1 = one lane to the left, -1 = right), pure pursuit."""
    # min(max()) is np.clip on these finite scalars (signed zeros too), without numpy's
    # per-call overhead; round() rounds half to even like np.rint.
    target_speed = float(min(max(action[0], 0.0), LIMITS.max_lane_speed))
    lane_change = round(float(min(max(action[1], -1.0), 1.0)))
    here = ctx.lane or ctx.road.nearest_lane(pose.x, pose.y, pose.heading)
    target = ctx.road.lanes.get(ctx.target_lane) if ctx.target_lane else None
    if target is None or target.edge_id != here.lane.edge_id:
        target = here.lane
    if lane_change and (target is here.lane or abs(here.t) < 0.5):
        siblings = ctx.road.edges[here.lane.edge_id]
        index = here.lane.index + lane_change
        if 0 <= index < len(siblings):
            target = siblings[index]
    ctx.target_lane = target.id
    acceleration = min(
        max((target_speed - pose.speed) / max(ctx.dt, 0.5), -LIMITS.max_deceleration),
        LIMITS.max_acceleration,
    )
    lookahead = max(4.0, 0.8 * pose.speed)
    aim_x, aim_y = _point_ahead(ctx, target.id, target.project(pose.x, pose.y)[0] + lookahead)
    alpha = wrap(math.atan2(aim_y - pose.y, aim_x - pose.x) - pose.heading)
    distance = max(math.hypot(aim_x - pose.x, aim_y - pose.y), 1e-3)
    steering = math.atan(2 * wheelbase(ctx.length) * math.sin(alpha) / distance)
    steering = min(max(steering, -LIMITS.max_steering), LIMITS.max_steering)
    return bicycle_step(pose, float(acceleration), steering, ctx.dt, ctx.length, LIMITS.max_speed)


def _point_ahead(ctx: ControlContext, lane_id: str, s: float) -> tuple[float, float]:
    """The centreline point ``s`` [m] along ``lane_id``, continuing into successors (preferring
    the mission route) past its end."""
    lane = ctx.road.lanes[lane_id]
    for _ in range(8):
        if s <= lane.length or not lane.successors:
            break
        s -= lane.length
        lane = preferred_successor(ctx.road, lane, ctx.route)
    return lane.point_at(s)


Decoder = Callable[[np.ndarray, Pose, ControlContext], Pose]

DECODERS: dict[ActionSpace, Decoder] = {
    ActionSpace.TargetPose: target_pose,
    ActionSpace.RelativeTargetPose: relative_target_pose,
    ActionSpace.Continuous: continuous,
    ActionSpace.LaneWithContinuousSpeed: lane_with_continuous_speed,
}
