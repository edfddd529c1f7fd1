"""The competition kit's ``FrameStack``: each agent's last ``num_stack`` observations as a tuple,
**newest first** (SMARTS ``comp-1`` and later push each frame on the left); after a reset the
first observation fills every slot. The observation space becomes, per agent, a ``Tuple`` of
``num_stack`` copies of the wrapped environment's space (when it has one), which wrappers built
on top (the kit's ``Concatenate``) read."""

from __future__ import annotations

import copy
from collections import deque

import gym


class FrameStack(gym.Wrapper):
    def __init__(self, env, num_stack: int = 3) -> None:
        if num_stack < 2:
            raise AssertionError(f"Expected num_stack > 1, but got {num_stack}.")
        super().__init__(env)
        self._num_stack = num_stack
        self._frames: dict[str, deque] = {}
        space = self.observation_space
        if space:
            self.observation_space = gym.spaces.Dict(
                {
                    agent_id: gym.spaces.Tuple([agent_space] * num_stack)
                    for agent_id, agent_space in space.spaces.items()
                }
            )

    def _stacked(self, obs: dict) -> dict:
        out = {}
        for agent_id, frame in obs.items():
            frames = self._frames.setdefault(agent_id, deque(maxlen=self._num_stack))
            frames.appendleft(frame)
            while len(frames) < self._num_stack:
                frames.appendleft(frame)
            out[agent_id] = copy.deepcopy(tuple(frames))
        return out

    def step(self, action):
        obs, rewards, dones, infos = self.env.step(action)
        return self._stacked(obs), rewards, dones, infos

    def reset(self, **kwargs):
        self._frames = {}
        return self._stacked(self.env.reset(**kwargs))
