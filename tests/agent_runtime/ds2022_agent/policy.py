"""A submission written the way Driving SMARTS 2022 agents were, run unmodified by the tests.

Like the competition kit's example (and the published 1st- and 3rd-place agents) it imports
SMARTS's helpers and gym, hands the evaluator its wrappers through ``submitted_wrappers()``
(``FormatObs``, ``FormatAction`` and a wrapper of its own that reads SMARTS's observation by
attribute), pins numpy in requirements.txt and uses ``np.float``, which numpy removed in 1.24:
it only runs if the pinned numpy is the one it imports.
"""

import sys
from pathlib import Path
from typing import Any, Dict

import gym
import numpy as np

# To import the submission folder, as the kit's template does.
sys.path.insert(0, str(Path(__file__).resolve().parents[0]))

from smarts.core.utils.math import radians_to_vec, vec_to_radians  # noqa: E402

DT = 0.1  # [s]
CRUISE = 10.0  # [m/s]


class BasePolicy:
    def act(self, obs: Dict[str, Any]):
        raise NotImplementedError


def submitted_wrappers():
    from observation import SaveGoal

    from smarts.core.controllers import ActionSpaceType
    from smarts.env.wrappers.format_action import FormatAction
    from smarts.env.wrappers.format_obs import FormatObs

    return [
        SaveGoal,
        FormatObs,
        lambda env: FormatAction(env=env, space=ActionSpaceType["TargetPose"]),
    ]


class Policy(BasePolicy):
    def __init__(self):
        self.space = gym.spaces.Box(low=-1e10, high=1e10, shape=(4,), dtype=np.float32)
        sys.stderr.write(f"ds2022 agent on numpy {np.__version__}\n")

    def act(self, obs: Dict[str, Any]):
        wrapped_act = {}
        for agent_id, agent_obs in obs.items():
            wrapped_act.update({agent_id: self.drive(agent_obs)})
        return wrapped_act

    def drive(self, o: Dict[str, Any]) -> np.ndarray:
        ego = o["ego_vehicle_state"]
        pos = np.array(ego["pos"][:2], dtype=np.float)  # np.float: numpy < 1.24 only
        paths = o["waypoint_paths"]["pos"][:, :, :2]  # (4, 20, 2), zero-padded
        valid = np.any(paths != 0, axis=-1)
        heading = float(ego["heading"])
        ahead = radians_to_vec(heading)
        best, best_cost = None, np.inf
        for index in range(paths.shape[0]):
            points = paths[index][valid[index]]
            if len(points) < 2:
                continue
            cost = float(np.min(np.linalg.norm(points - pos, axis=1)))
            if cost < best_cost:
                best, best_cost = points, cost
        speed = min(CRUISE, float(ego["speed"]) + 3.0 * DT)
        if best is None:
            target = pos + ahead * speed * DT
            return np.array([*target, heading, DT], dtype=np.float32)
        nearest = int(np.argmin(np.linalg.norm(best - pos, axis=1)))
        aim = best[min(nearest + 4, len(best) - 1)]
        to_aim = aim - pos
        distance = float(np.linalg.norm(to_aim))
        if distance < 1e-6:
            return np.array([*pos, heading, DT], dtype=np.float32)
        step = to_aim / distance * speed * DT
        return np.array([*(pos + step), vec_to_radians(step), DT], dtype=np.float32)
