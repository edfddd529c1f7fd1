"""The per-agent-step terms of humanness and rules (scoring spec, metrics 3 and 4).

Each term takes one agent's driven rows (an :class:`AgentTrack`, arrays of shape ``(n,)`` and
neighbours ``(n, K)``) and the profile's constants, and returns ``(n,)`` floats.
"""

from __future__ import annotations

import numpy as np

from arena import portable_math
from evaluator.scoring.record import AgentTrack
from evaluator.scoring.term import Term, TermParameters


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles [rad] wrapped to [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def distance_obs(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """Closeness to the nearest vehicle ahead: max ``exp(-decay * d)`` over the vehicles within
    ``headway x speed`` [m] of the ego centre and within the half-angle of its heading."""
    dx = track.nbr_x - track.x[:, None]  # (n, K) [m]
    dy = track.nbr_y - track.y[:, None]
    distance = np.hypot(dx, dy)
    moving = track.speed[:, None] > 0.0
    reach = profile.obs_headway_s * track.speed[:, None]  # [m]
    # The angles and exponentials of the few vehicles in reach only: portable_math's are the C
    # library's, one element at a time.
    near = track.nbr_valid & moving & (distance <= reach)
    heading = np.broadcast_to(track.heading[:, None], near.shape)
    off_heading = np.abs(wrap_angle(portable_math.arctan2(dy[near], dx[near]) - heading[near]))
    ahead = off_heading <= np.deg2rad(profile.obs_half_angle_deg)
    closeness = np.zeros(near.shape)
    closeness[near] = np.where(
        ahead, portable_math.exp(-profile.obs_decay_per_m * distance[near]), 0.0
    )
    return closeness.max(axis=1, initial=0.0)


def jerk(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """``|a_t - a_(t-1)| / dt`` [m/s^3] from the velocity vector; 0 on the first two rows, which
    have no earlier acceleration to compare with."""
    velocity = np.stack([track.vx, track.vy], axis=1)  # (n, 2) [m/s]
    accel = np.diff(velocity, axis=0) / profile.dt_s  # (n-1, 2): row i is the accel at row i+1
    out = np.zeros(len(track.x))
    out[2:] = np.linalg.norm(np.diff(accel, axis=0), axis=1) / profile.dt_s
    return out


def lc_off(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """``(distance from the lane centre / lane width)^2``."""
    return (track.lane_offset / track.lane_width) ** 2


def speeding(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """``min(max(0, speed - limit) / (fraction x limit), 1)``: 0 at the limit, 1 from
    ``(1 + fraction) x limit`` on."""
    over = np.maximum(track.speed - track.speed_limit, 0.0)  # [m/s]
    return np.minimum(over / (profile.speeding_tolerance_fraction * track.speed_limit), 1.0)


def wrong_way(track: AgentTrack, profile: TermParameters) -> np.ndarray:
    """1 where the heading is more than the profile's angle from the lane direction, outside
    junctions (lane directions inside a junction do not say which way is right)."""
    against = np.abs(wrap_angle(track.heading - track.lane_heading)) > np.deg2rad(
        profile.wrong_way_angle_deg
    )
    return (against & ~track.in_junction).astype(float)


# The terms of this module by the name profiles give them (evaluator.scoring.registry).
TERMS: dict[str, Term] = {
    "distance_obs": distance_obs,
    "jerk": jerk,
    "lc_off": lc_off,
    "speeding": speeding,
    "wrong_way": wrong_way,
}
