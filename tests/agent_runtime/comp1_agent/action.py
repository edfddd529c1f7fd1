"""A discrete action wrapper in the kit's manner: 4 choices turned into a TargetPose from the pose
``SaveObs`` kept (read through the wrapper chain as ``self.saved_obs``)."""

import math

import gym
import numpy as np

DT = 0.1  # [s]
STEP = 30 / 3.6 * DT  # [m] at 30 km/h
TURN = math.radians(5)
# choice -> (distance [m], heading change [rad]): stop, straight, left, right
CHOICES = {0: (0.0, 0.0), 1: (STEP, 0.0), 2: (STEP, TURN), 3: (STEP, -TURN)}


class Action(gym.ActionWrapper):
    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.action_space = gym.spaces.Dict(
            {agent_id: gym.spaces.Discrete(n=len(CHOICES)) for agent_id in env.action_space.spaces}
        )

    def action(self, action):
        poses = {}
        for agent_id, choice in action.items():
            pose = self.saved_obs[agent_id]
            distance, turn = CHOICES[int(choice)]
            heading = (pose["heading"] + turn + np.pi) % (2 * np.pi) - np.pi
            # SMARTS's headings: 0 points north (+y), counter-clockwise.
            x = pose["pos"][0] - distance * np.sin(heading)
            y = pose["pos"][1] + distance * np.cos(heading)
            poses[agent_id] = np.array([x, y, heading, DT], dtype=np.float32)
        return poses
