"""Observation wrappers in the kit's manner, reading comp-1's FormatObs keys (``ego``, ``mission``,
``rgb``, ``waypoints``) and SMARTS's colours."""

import copy

import gym
import numpy as np


class SaveObs(gym.ObservationWrapper):
    """Keeps each agent's position and heading for the action wrapper."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.saved_obs = {}

    def observation(self, obs):
        self.saved_obs = {
            agent_id: {
                "pos": copy.deepcopy(o["ego"]["pos"]),
                "heading": copy.deepcopy(o["ego"]["heading"]),
            }
            for agent_id, o in obs.items()
        }
        return obs


def _rgb(colour) -> np.ndarray:
    return np.array(colour.value[:3]) * 255


class FilterObs(gym.ObservationWrapper):
    """A channels-first top-down image without the road, the route's waypoints painted on it, and
    the goal's distance and heading relative to the ego."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        from smarts.core.colors import Colors, SceneColors

        self._road = _rgb(SceneColors.Road)
        self._waypoint = _rgb(Colors.GreenTransparent)
        self._setting = {}
        spaces = {}
        for agent_id, space in env.observation_space.spaces.items():
            rgb = env.agent_specs[agent_id].interface.rgb
            self._setting[agent_id] = (rgb.width, rgb.height, rgb.resolution)
            h, w, c = space["rgb"].shape
            spaces[agent_id] = gym.spaces.Dict(
                {
                    "rgb": gym.spaces.Box(low=0, high=255, shape=(c, h, w), dtype=np.uint8),
                    "goal_distance": gym.spaces.Box(-1e10, 1e10, shape=(1, 1), dtype=np.float32),
                    "goal_heading": gym.spaces.Box(-np.pi, np.pi, shape=(1, 1), dtype=np.float32),
                }
            )
        self.observation_space = gym.spaces.Dict(spaces)

    def observation(self, obs):
        return {agent_id: self._filter(agent_id, o) for agent_id, o in obs.items()}

    def _filter(self, agent_id, o):
        pos, heading = o["ego"]["pos"], float(o["ego"]["heading"])
        to_goal = o["mission"]["goal_pos"] - pos
        goal_angle = np.arctan2(-to_goal[0], to_goal[1])  # SMARTS: 0 north, counter-clockwise
        relative = (goal_angle - heading + np.pi) % (2 * np.pi) - np.pi
        rgb = o["rgb"].copy()
        rgb[np.all(rgb == self._road, axis=-1)] = 0
        width, height, resolution = self._setting[agent_id]
        for point in o["waypoints"]["pos"][:3, 3:].reshape(-1, 3):  # 3 paths, from 3 m ahead
            if not point.any():
                continue
            dx, dy = point[0] - pos[0], point[1] - pos[1]
            # Into the ego frame, heading up: column to the right, row downwards.
            right = dx * np.cos(heading) + dy * np.sin(heading)
            ahead = -dx * np.sin(heading) + dy * np.cos(heading)
            col = int(round(width / 2 + right / resolution))
            row = int(round(height / 2 - ahead / resolution))
            if 0 <= row < height and 0 <= col < width:
                rgb[row, col] = self._waypoint
        return {
            "rgb": rgb.transpose(2, 0, 1).astype(np.uint8),
            "goal_distance": np.array([[np.linalg.norm(to_goal[:2])]], dtype=np.float32),
            "goal_heading": np.array([[relative]], dtype=np.float32),
        }


class Concatenate(gym.ObservationWrapper):
    """The stacked frames of each key joined along the channel axis (``first`` or ``last``)."""

    def __init__(self, env: gym.Env, channels_order: str = "first"):
        super().__init__(env)
        self._axis = {"first": 0, "last": -1}[channels_order]
        spaces = {}
        for agent_id, stacked in env.observation_space.spaces.items():
            frames = len(stacked)
            spaces[agent_id] = gym.spaces.Dict(
                {
                    key: gym.spaces.Box(
                        low=np.concatenate([space.low] * frames, axis=self._axis),
                        high=np.concatenate([space.high] * frames, axis=self._axis),
                        dtype=space.dtype,
                    )
                    for key, space in stacked[0].spaces.items()
                }
            )
        self.observation_space = gym.spaces.Dict(spaces)

    def observation(self, obs):
        return {
            agent_id: {
                key: np.concatenate([frame[key] for frame in frames], axis=self._axis)
                for key in frames[0]
            }
            for agent_id, frames in obs.items()
        }
