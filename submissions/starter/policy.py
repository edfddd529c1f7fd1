"""A starting agent: keep the current lane at its speed limit.

Uses the ``LaneWithContinuousSpeed`` action space (see ``agent.yaml``): the simulator's built-in
controller steers along the lane, this policy only chooses [target_speed m/s, lane_change]. Every
observation field and action space is described in the Driving Arena ``docs/agent-interface.md``.
"""

CRUISE_SPEED = 13.9  # [m/s] when the waypoints carry no speed limit (50 km/h)


class Policy:
    def __init__(self) -> None:
        # The working directory is this folder: load model files with relative paths here.
        pass

    def reset(self) -> None:
        """A new episode starts."""

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return {agent_id: [target_speed(agent_obs), 0.0] for agent_id, agent_obs in obs.items()}


def target_speed(obs: dict) -> float:
    """The speed limit [m/s] of the ego's own lane."""
    lane_index = obs["ego_vehicle_state"]["lane_index"]
    for path in obs.get("waypoint_paths") or []:
        if path and path[0]["lane_index"] == lane_index:
            return path[0]["speed_limit"] or CRUISE_SPEED
    return CRUISE_SPEED
