"""A random agent that still drives legal actions: a baseline for the leaderboard's bottom row.

Each step it picks a point a random distance (0 to 2.8 m, the TargetPose limit per 0.1 s step)
along its first waypoint path, nudged sideways by a little noise, and asks to be there with the
path's heading. Seeded, so two runs of the same scenario drive the same way.
"""

import math

import numpy as np

LATERAL_NOISE = 0.3  # [m]


class Policy:
    def __init__(self) -> None:
        self.rng = np.random.default_rng(7)

    def reset(self) -> None:
        self.rng = np.random.default_rng(7)

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return {agent_id: self.target_pose(agent_obs) for agent_id, agent_obs in obs.items()}

    def target_pose(self, obs: dict) -> list[float]:
        ego = obs["ego_vehicle_state"]
        x, y = ego["position"][0], ego["position"][1]
        heading = ego["heading"]
        paths = [path for path in obs.get("waypoint_paths") or [] if path]
        if paths:
            path = paths[int(self.rng.integers(len(paths)))]
            # Waypoints are 1 m apart: the first three are all within one step's reach.
            waypoint = path[min(int(self.rng.integers(0, 3)), len(path) - 1)]
            (x, y), heading = waypoint["pos"], waypoint["heading"]
        offset = self.rng.normal(0.0, LATERAL_NOISE)
        x -= offset * math.sin(heading)
        y += offset * math.cos(heading)
        return [float(x), float(y), float(heading), float(obs.get("dt", 0.1))]
