"""render_mode="rgb_array": a top-down picture of the episode after every reset and step (the
terminal one too), through gymnasium.make, in this process and in a simulator subprocess; and
the default action space samples actions that drive."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.wrappers import RenderCollection

from learn.gym_env import DrivingArenaEnv
from learn.registration import ENV_ID
from learn.render import GOAL_COLOUR, RENDER_PIXELS
from sim.bev import COLOURS
from tests.learn.conftest import PUBLIC

CRUISE = PUBLIC / "p016_cruise_2lane_low"


def has_colour(image: np.ndarray, rgb) -> bool:
    return bool(np.all(image == np.asarray(rgb, np.uint8), axis=-1).any())


@pytest.mark.parametrize("simulator", ["in_process", "subprocess"])
def test_render_rgb_array_pictures_every_step_to_the_end(closing, simulator):
    env = RenderCollection(
        gymnasium.make(ENV_ID, scenario=CRUISE, render_mode="rgb_array", simulator=simulator)
    )
    closing(env)
    env.reset(seed=0)
    first = env.unwrapped.render()
    assert first.shape == (RENDER_PIXELS, RENDER_PIXELS, 3) and first.dtype == np.uint8
    # The agent at the centre, the road around it.
    middle = first[RENDER_PIXELS // 2 - 3 : RENDER_PIXELS // 2 + 3, RENDER_PIXELS // 2 - 3 :]
    assert has_colour(middle, COLOURS["ego"])
    assert has_colour(first, COLOURS["route"]) or has_colour(first, COLOURS["road"])
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.array([12.0, 0.0], np.float32))
        steps, done = steps + 1, terminated or truncated
    frames = env.render()  # RenderCollection: one picture per reset and step
    assert len(frames) == steps + 1
    # The last one is the terminal step's: near its goal, which is drawn.
    assert has_colour(frames[-1], GOAL_COLOUR)
    assert not np.array_equal(frames[0], frames[-1])


def test_without_render_mode_render_is_none_and_a_wrong_mode_is_refused(closing):
    env = DrivingArenaEnv(CRUISE)
    closing(env)
    env.reset(seed=0)
    assert env.render() is None
    with pytest.raises(ValueError, match="rgb_array"):
        DrivingArenaEnv(CRUISE, render_mode="human")


def test_the_default_action_space_samples_actions_that_drive(closing):
    env = gymnasium.make(ENV_ID, scenario=CRUISE)
    closing(env)
    space = env.action_space
    assert np.all(np.isfinite(space.low)) and np.all(np.abs(space.high) < 100)
    env.reset(seed=0)
    env.action_space.seed(0)
    _, _, terminated, _, info = env.step(env.action_space.sample())
    assert not terminated or info["done_reason"] != "invalid_action"
