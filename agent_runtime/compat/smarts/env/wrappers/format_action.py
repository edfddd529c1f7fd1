"""The competition kit's ``FormatAction``: one gym action space for every agent, and actions cast
as SMARTS's wrapper casts them (float32 arrays; lane action indices to names)."""

from __future__ import annotations

import gym
import numpy as np
from smarts.core.controllers import ActionSpaceType

LANE_ACTIONS = ("keep_lane", "slow_down", "change_lane_left", "change_lane_right")


def _as_float32(action: dict) -> dict:
    return {k: np.asarray(v).astype(np.float32) for k, v in action.items()}


def _lane(action: dict) -> dict:
    return {k: LANE_ACTIONS[v] for k, v in action.items()}


_SPACES = {
    "Continuous": lambda: gym.spaces.Box(
        low=np.array([0.0, 0.0, -1.0]), high=np.array([1.0, 1.0, 1.0]), dtype=np.float32
    ),
    "ActuatorDynamic": lambda: gym.spaces.Box(
        low=np.array([0.0, 0.0, -1.0]), high=np.array([1.0, 1.0, 1.0]), dtype=np.float32
    ),
    "Lane": lambda: gym.spaces.Discrete(len(LANE_ACTIONS)),
    "TargetPose": lambda: gym.spaces.Box(
        low=np.array([-1e10, -1e10, -np.pi, 0]),
        high=np.array([1e10, 1e10, np.pi, 1e10]),
        dtype=np.float32,
    ),
}


class FormatAction(gym.ActionWrapper):
    """Gives every agent the action space ``space``; only Continuous, Lane, ActuatorDynamic and
    TargetPose, as in SMARTS."""

    def __init__(self, env, space: ActionSpaceType) -> None:
        super().__init__(env)
        name = space.name if isinstance(space, ActionSpaceType) else str(space)
        if name not in _SPACES:
            raise ValueError(f"FormatAction does not support the action space {name}")
        self._cast = _lane if name == "Lane" else _as_float32
        agent_ids = getattr(env, "agent_ids", None) or list(env.agent_specs)
        self.action_space = gym.spaces.Dict({agent_id: _SPACES[name]() for agent_id in agent_ids})

    def action(self, action: dict) -> dict:
        return self._cast(action)
