"""Incremental twins of the evaluator's metric terms, for the env's per-step ``info``.

The evaluator computes each term (:mod:`evaluator.scoring.registry`) over an agent's whole record;
a training step wants only the newest row's value, and recomputing over the track each step costs
more than the rest of the term bookkeeping together. A running term is fed the agent's record
rows one at a time, oldest first, and returns the newest row's value, equal to the evaluator's
term on the full record at that row (``tests/learn/test_running_terms.py`` holds them to it on
recorded episodes, for every term and profile). It keeps only what its formula looks back at
(the last velocities and headings, a running sum), so a step costs the same at step 5 and 500.

Plain Python floats and :mod:`math` throughout: on one row, numpy's per-call overhead is most of
the cost. Each formula mirrors its numpy original operation for operation, so the values agree to
the last bit wherever libm and numpy round alike (``hypot``, ``atan2`` and ``exp`` may differ in
the last place).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

from evaluator.scoring.term import TermParameters
from sim.record import RecordRow

_TWO_PI = 2 * math.pi  # the period evaluator.scoring.terms.wrap_angle uses


def wrap_angle(angle: float) -> float:
    """``angle`` [rad] wrapped to [-pi, pi), as :func:`evaluator.scoring.terms.wrap_angle`
    (Python's float ``%`` and numpy's take the sign of the divisor alike)."""
    return (angle + math.pi) % _TWO_PI - math.pi


class RunningTerm(Protocol):
    def update(self, row: RecordRow) -> float:
        """The term's value at ``row``, the agent's next record row."""
        ...


class Closeness:
    """:func:`evaluator.scoring.terms.distance_obs`: the largest ``exp(-decay * d)`` over the
    neighbours within ``headway x speed`` of the ego and the half-angle of its heading.

    A row's neighbours are nearest first (``docs/records.md``) and closeness falls with distance,
    so the first neighbour ahead is the largest: the rest are not looked at.
    """

    def __init__(self, profile: TermParameters) -> None:
        self._headway = profile.obs_headway_s
        self._half_angle = math.radians(profile.obs_half_angle_deg)
        self._decay = profile.obs_decay_per_m

    def update(self, row: RecordRow) -> float:
        speed = row.speed
        nbr = row.neighbours
        count = len(nbr)
        if not speed > 0.0 or not count:
            return 0.0
        reach = self._headway * speed  # [m]
        x, y, heading = row.x, row.y, row.heading
        # Read value by value: the loop mostly stops at the second or third neighbour, and a
        # memoryview's item is a plain float without converting the rest.
        values = memoryview(nbr.values)
        for i in range(count):
            dx, dy = values[i, 0] - x, values[i, 1] - y
            # A neighbour farther than reach along either axis is farther in a straight line:
            # skipped before the costly functions, with the same verdict.
            if abs(dx) > reach or abs(dy) > reach:
                continue
            distance = math.hypot(dx, dy)
            if distance > reach:
                return 0.0  # and so are all the rest
            # wrap_angle inline: a call is a fifth of an iteration's cost
            off_heading = (math.atan2(dy, dx) - heading + math.pi) % _TWO_PI - math.pi
            if abs(off_heading) <= self._half_angle:
                return math.exp(-self._decay * distance)
        return 0.0


class ClosenessRunningMean:
    """:func:`evaluator.scoring.reference_terms.distance_obs_running_mean`: the mean of
    :class:`Closeness` over the steps with a vehicle ahead so far, at such a step; 0 at a step
    with nothing ahead."""

    def __init__(self, profile: TermParameters) -> None:
        self._closeness = Closeness(profile)
        self._sum = 0.0  # summed in row order, as numpy's cumsum
        self._count = 0

    def update(self, row: RecordRow) -> float:
        value = self._closeness.update(row)
        self._sum += value
        if value == 0.0:
            return 0.0  # the mean lives on for the next step with a vehicle ahead
        self._count += 1
        return self._sum / self._count


class _Acceleration:
    """The velocity-vector acceleration of the last two rows, shared by both jerk terms:
    ``accel`` of row t is ``(v_t - v_(t-1)) / dt``, as ``np.diff(velocity) / dt``."""

    def __init__(self, dt: float) -> None:
        self._dt = dt
        self.rows = 0  # rows seen
        self._velocity: tuple[float, float] | None = None
        self.accel: tuple[float, float] | None = None  # at the newest row
        self.previous: tuple[float, float] | None = None  # at the row before

    def update(self, row: RecordRow) -> None:
        self.rows += 1
        vx, vy = row.vx, row.vy
        if self._velocity is not None:
            self.previous = self.accel
            px, py = self._velocity
            self.accel = ((vx - px) / self._dt, (vy - py) / self._dt)
        self._velocity = (vx, vy)


class Jerk:
    """:func:`evaluator.scoring.terms.jerk`: ``|a_t - a_(t-1)| / dt``, 0 on the first two
    rows."""

    def __init__(self, profile: TermParameters) -> None:
        self._dt = profile.dt_s
        self._accel = _Acceleration(profile.dt_s)

    def update(self, row: RecordRow) -> float:
        accel = self._accel
        accel.update(row)
        if accel.previous is None:
            return 0.0
        dx = accel.accel[0] - accel.previous[0]
        dy = accel.accel[1] - accel.previous[1]
        return math.sqrt(dx * dx + dy * dy) / self._dt  # np.linalg.norm's sqrt of the squares


class JerkSquaredChange:
    """:func:`evaluator.scoring.reference_terms.jerk_squared_change`: the squared change of the
    acceleration vector plus that of the angular acceleration (from the fourth row on)."""

    def __init__(self, profile: TermParameters) -> None:
        self._dt = profile.dt_s
        self._accel = _Acceleration(profile.dt_s)
        self._heading: float | None = None
        self._yaw_rate: float | None = None  # [rad/s] at the newest row
        self._angular_accel: float | None = None  # [rad/s^2] at the newest row

    def update(self, row: RecordRow) -> float:
        accel = self._accel
        accel.update(row)
        previous_angular = self._angular_accel
        if self._heading is not None:
            yaw_rate = wrap_angle(row.heading - self._heading) / self._dt
            if self._yaw_rate is not None:
                self._angular_accel = (yaw_rate - self._yaw_rate) / self._dt
            self._yaw_rate = yaw_rate
        self._heading = row.heading
        if accel.previous is None:
            return 0.0
        dx = accel.accel[0] - accel.previous[0]
        dy = accel.accel[1] - accel.previous[1]
        out = dx * dx + dy * dy
        if previous_angular is not None:
            change = self._angular_accel - previous_angular
            out += change * change
        return out


class LaneOffset:
    """:func:`evaluator.scoring.terms.lc_off` (``half_width=False``) and
    :func:`evaluator.scoring.reference_terms.lc_off_half_width`: the squared offset from the lane
    centre over the lane width or half of it."""

    def __init__(self, profile: TermParameters, *, half_width: bool) -> None:
        self._half_width = half_width

    def update(self, row: RecordRow) -> float:
        width = row.lane_width / 2 if self._half_width else row.lane_width
        ratio = row.lane_offset / width
        return ratio * ratio


class Speeding:
    """:func:`evaluator.scoring.terms.speeding`."""

    def __init__(self, profile: TermParameters) -> None:
        self._fraction = profile.speeding_tolerance_fraction

    def update(self, row: RecordRow) -> float:
        over = max(row.speed - row.speed_limit, 0.0)  # [m/s]
        return min(over / (self._fraction * row.speed_limit), 1.0)


class WrongWay:
    """:func:`evaluator.scoring.terms.wrong_way`."""

    def __init__(self, profile: TermParameters) -> None:
        self._angle = math.radians(profile.wrong_way_angle_deg)

    def update(self, row: RecordRow) -> float:
        if row.in_junction:
            return 0.0
        return float(abs(wrap_angle(row.heading - row.lane_heading)) > self._angle)


# The running twin of each registered metric term, by the registry's names: a new one per agent
# and episode.
RUNNING_TERMS: dict[str, Callable[[TermParameters], RunningTerm]] = {
    "distance_obs": Closeness,
    "distance_obs_running_mean": ClosenessRunningMean,
    "jerk": Jerk,
    "jerk_squared_change": JerkSquaredChange,
    "lc_off": lambda profile: LaneOffset(profile, half_width=False),
    "lc_off_half_width": lambda profile: LaneOffset(profile, half_width=True),
    "speeding": Speeding,
    "wrong_way": WrongWay,
}
