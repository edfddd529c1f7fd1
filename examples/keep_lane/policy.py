"""Keep the current lane at the speed limit, and follow the vehicle ahead at a safe gap.

Uses the ``LaneWithContinuousSpeed`` action space: the simulator's lane-keeping controller steers,
this policy only chooses the target speed and never changes lane. The gap rule is a constant time
headway: aim for the lead vehicle's speed plus the spare distance covered in ``HEADWAY`` seconds.
"""

import math

CRUISE_SPEED = 13.9  # [m/s] when the map gives no speed limit (50 km/h)
MIN_GAP = 8.0  # [m] bumper to bumper, kept even when stopped
HEADWAY = 1.5  # [s]
LOOK_AHEAD = 60.0  # [m]


class Policy:
    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return {agent_id: [target_speed(agent_obs), 0.0] for agent_id, agent_obs in obs.items()}


def target_speed(obs: dict) -> float:
    ego = obs["ego_vehicle_state"]
    limit, lane_width = lane_limits(obs)
    lead = lead_vehicle(ego, obs.get("neighborhood_vehicle_states") or [], lane_width)
    if lead is None:
        return limit
    gap, lead_speed = lead
    return max(0.0, min(limit, lead_speed + (gap - MIN_GAP) / HEADWAY))


def lane_limits(obs: dict) -> tuple[float, float]:
    """Speed limit [m/s] and width [m] of the lane the ego is in."""
    lane_index = obs["ego_vehicle_state"].get("lane_index")
    paths = [path for path in obs.get("waypoint_paths") or [] if path]
    for path in paths:
        if path[0].get("lane_index") == lane_index:
            return path[0].get("speed_limit") or CRUISE_SPEED, path[0].get("lane_width") or 3.2
    if paths:
        return paths[0][0].get("speed_limit") or CRUISE_SPEED, paths[0][0].get("lane_width") or 3.2
    return CRUISE_SPEED, 3.2


def lead_vehicle(ego: dict, neighbours: list[dict], lane_width: float):
    """(gap [m], speed [m/s]) of the nearest vehicle ahead in the ego's lane, or None."""
    x, y = ego["position"][0], ego["position"][1]
    cos_h, sin_h = math.cos(ego["heading"]), math.sin(ego["heading"])
    ego_half_length = ego["bounding_box"][0] / 2
    best = None
    for other in neighbours:
        dx, dy = other["position"][0] - x, other["position"][1] - y
        ahead = dx * cos_h + dy * sin_h
        aside = -dx * sin_h + dy * cos_h
        if ahead <= 0 or ahead > LOOK_AHEAD or abs(aside) > lane_width / 2:
            continue
        gap = ahead - ego_half_length - other["bounding_box"][0] / 2
        if best is None or gap < best[0]:
            best = (gap, other["speed"])
    return best
