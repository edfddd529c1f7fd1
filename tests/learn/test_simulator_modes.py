"""Where an environment's simulator runs: in the environment's process when it is free, else in a
child process; both give the same episodes."""

from __future__ import annotations

import numpy as np
import pytest

from learn.gym_env import DrivingArenaEnv
from learn.session import InProcessSimulator
from learn.worker import SimulatorProcess
from tests.learn.conftest import PUBLIC

CRUISE = PUBLIC / "p016_cruise_2lane_low"


def _leaves(obs: dict, path: str = ""):
    for name, value in sorted(obs.items()):
        if isinstance(value, dict):
            yield from _leaves(value, f"{path}{name}.")
        else:
            yield f"{path}{name}", value


@pytest.mark.slow
def test_in_process_and_child_process_give_the_same_episode(closing) -> None:
    here = DrivingArenaEnv(
        CRUISE,
        action_space="LaneWithContinuousSpeed",
        top_down_rgb=True,
        img_pixels=32,
        simulator="in_process",
    )
    child = DrivingArenaEnv(
        CRUISE,
        action_space="LaneWithContinuousSpeed",
        top_down_rgb=True,
        img_pixels=32,
        simulator="subprocess",
    )
    closing(here)
    closing(child)
    outs = [env.reset(seed=4) for env in (here, child)]
    assert isinstance(here._simulator, InProcessSimulator)
    assert isinstance(child._simulator, SimulatorProcess)
    for step in range(60):
        action = np.array([6.0 + step % 5, (step // 20) % 2], np.float32)
        outs = [env.step(action) for env in (here, child)]
        (obs_a, reward_a, *ends_a, info_a), (obs_b, reward_b, *ends_b, info_b) = outs
        for (name, a), (_, b) in zip(_leaves(obs_a), _leaves(obs_b), strict=True):
            np.testing.assert_array_equal(a, b, err_msg=f"step {step}: {name}")
        assert (reward_a, ends_a, info_a) == (reward_b, ends_b, info_b)
        if any(ends_a):
            break


@pytest.mark.slow
def test_auto_gives_a_second_env_in_this_process_a_child(closing, short_road) -> None:
    first = DrivingArenaEnv(short_road, action_space="Continuous")
    second = DrivingArenaEnv(short_road, action_space="Continuous")
    closing(first)
    closing(second)
    first.reset(seed=0)
    second.reset(seed=0)
    assert isinstance(first._simulator, InProcessSimulator)
    assert isinstance(second._simulator, SimulatorProcess)
    # The first env keeps this process's simulator slot between its episodes.
    forced = DrivingArenaEnv(short_road, action_space="Continuous", simulator="in_process")
    closing(forced)
    with pytest.raises(RuntimeError, match="already runs a simulation"):
        forced.reset(seed=0)
    first.close()
    forced.reset(seed=0)
    assert isinstance(forced._simulator, InProcessSimulator)


def test_an_unknown_simulator_mode_is_refused() -> None:
    with pytest.raises(ValueError, match="in_process"):
        DrivingArenaEnv(PUBLIC, simulator="thread")
