"""The competition kit's ``FrameStack``: each agent's last ``num_stack`` observations, oldest
first, as a tuple; after a reset the first observation fills every slot."""

from __future__ import annotations

import copy
from collections import deque

import gym


class FrameStack(gym.Wrapper):
    def __init__(self, env, num_stack: int = 3) -> None:
        if num_stack < 1:
            raise ValueError(f"num_stack must be at least 1, got {num_stack}")
        super().__init__(env)
        self._num_stack = num_stack
        self._frames: dict[str, deque] = {}

    def _stacked(self, obs: dict) -> dict:
        out = {}
        for agent_id, frame in obs.items():
            frames = self._frames.get(agent_id)
            if frames is None:
                frames = deque(
                    (copy.deepcopy(frame) for _ in range(self._num_stack - 1)),
                    maxlen=self._num_stack,
                )
                self._frames[agent_id] = frames
            frames.append(frame)
            out[agent_id] = tuple(frames)
        return out

    def step(self, action):
        obs, rewards, dones, infos = self.env.step(action)
        stacked = self._stacked(obs)
        for agent_id, done in dones.items():
            if done and agent_id != "__all__":  # its last frame is stacked: forget it
                self._frames.pop(agent_id, None)
        return stacked, rewards, dones, infos

    def reset(self, **kwargs):
        self._frames = {}
        return self._stacked(self.env.reset(**kwargs))
