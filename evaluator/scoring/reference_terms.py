"""Terms of the ``driving-smarts-2022-reference`` profile: the formulas of the competition's own
evaluation code, where they differ from the paper's (``docs/scoring.md`` compares them).

Same contract as :mod:`evaluator.scoring.terms`: one agent's driven rows in, ``(n,)`` floats out.
"""

from __future__ import annotations

import numpy as np

from evaluator.scoring.record import AgentTrack
from evaluator.scoring.term import Term, TermParameters
from evaluator.scoring.terms import distance_obs, wrap_angle


def jerk_squared_change(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """``|a_t - a_(t-1)|^2 + (alpha_t - alpha_(t-1))^2``: the squared change between steps of
    the acceleration vector [m/s^2] plus that of the angular acceleration [rad/s^2], not
    divided by dt; 0 on the first two rows (no earlier acceleration)."""
    dt = profile.dt_s
    velocity = np.stack([track.vx, track.vy], axis=1)  # (n, 2) [m/s]
    accel = np.diff(velocity, axis=0) / dt  # (n-1, 2): row i is the accel at row i+1
    yaw_rate = wrap_angle(np.diff(track.heading)) / dt  # (n-1,) [rad/s]
    angular_accel = np.diff(yaw_rate) / dt  # (n-2,): row i is at row i+2
    out = np.zeros(len(track.x))
    if len(track.x) > 2:
        out[2:] = (np.diff(accel, axis=0) ** 2).sum(axis=1)
    if len(track.x) > 3:
        out[3:] += np.diff(angular_accel) ** 2
    return out


def lc_off_half_width(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """``(distance from the lane centre / (lane width / 2))^2``: 1 on the lane's edge."""
    return (track.lane_offset / (track.lane_width / 2)) ** 2


def distance_obs_running_mean(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """At a step with a vehicle ahead, the running mean of :func:`distance_obs` over the steps
    with a vehicle ahead so far; 0 at a step with nothing ahead. The competition code returns 0
    on such a step (its running mean lives on for the next obstacle) and the agent-episode keeps
    the last step's value, so an episode whose last step has nothing ahead scores 0."""
    value = distance_obs(track, profile)
    ahead = value > 0.0
    count = np.cumsum(ahead)
    return np.where(ahead, np.cumsum(value) / np.maximum(count, 1), 0.0)


# The terms of this module by the name profiles give them (evaluator.scoring.registry).
TERMS: dict[str, Term] = {
    "jerk_squared_change": jerk_squared_change,
    "lc_off_half_width": lc_off_half_width,
    "distance_obs_running_mean": distance_obs_running_mean,
}
