"""The Gymnasium environment: API conformance, the evaluator's own step, episode ends, reward."""

from __future__ import annotations

import functools
import itertools
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from arena.scenario import load_scenario
from learn.gym_env import DrivingArenaEnv
from learn.reward import RewardInput
from sim.episode import run_episode
from sim.interface import ActionSpace, AgentInterface
from tests.learn.conftest import PUBLIC
from tests.settings import env_only

CRUISE = PUBLIC / "p016_cruise_2lane_low"


def test_passes_gymnasiums_env_checker_with_rasters(closing) -> None:
    env = DrivingArenaEnv(
        CRUISE,
        action_space="LaneWithContinuousSpeed",
        top_down_rgb=True,
        occupancy_grid_map=True,
        drivable_area_grid_map=True,
        img_pixels=64,
    )
    closing(env)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert obs["top_down_rgb"].shape == (64, 64, 3) and obs["top_down_rgb"].any()


@pytest.mark.slow  # stable-baselines3's import (torch): seconds of CPU in a fast-tier process
def test_passes_stable_baselines3s_env_checker_unwrapped(closing) -> None:
    """SB3 indexes each top-level box's out-of-bounds entries: no leaf may be 0-d."""
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = DrivingArenaEnv(CRUISE, action_space="LaneWithContinuousSpeed")
    closing(env)
    with pytest.warns(UserWarning, match="Nested observation spaces"):
        env_checker.check_env(env)
    obs, _ = env.reset(seed=0)
    assert obs["step_count"].shape == (1,) and obs["ego_vehicle_state"]["speed"].shape == (1,)


class Repeat:
    """An in-process agent for the evaluator's episode loop: the same action every step."""

    def __init__(self, action: list[float]) -> None:
        self.action = action

    def reset(self) -> None:
        pass

    def act(self, obs: dict) -> dict:
        return {agent_id: self.action for agent_id in obs}

    def close(self) -> None:
        pass


def test_a_kept_observation_is_not_changed_by_later_steps(closing) -> None:
    """Training loops keep observations (replay buffers, frame stacks), so each one's arrays are
    its own: no later step writes into them (the simulator rewrites its record every step)."""
    env = DrivingArenaEnv(CRUISE, action_space="LaneWithContinuousSpeed")
    closing(env)
    flatten = functools.partial(gymnasium.spaces.utils.flatten, env.observation_space)
    obs, _ = env.reset(seed=0)
    kept = [(obs, flatten(obs))]
    for _ in range(5):
        obs, *_ = env.step(np.array([9.0, 0.0], np.float32))
        kept.append((obs, flatten(obs)))
    for observation, values in kept:
        np.testing.assert_array_equal(flatten(observation), values)
    for (earlier, _), (later, _) in itertools.pairwise(kept):
        position = earlier["ego_vehicle_state"]["position"]
        assert not np.shares_memory(position, later["ego_vehicle_state"]["position"])
    assert len({values.tobytes() for _, values in kept}) == len(kept)  # the ego moved


def test_an_episode_is_the_evaluators_episode(closing, tmp_path) -> None:
    """Driving the env and the evaluator's episode loop with the same actions ends the same way
    on the same step, at the same place (same simulator, decoding, events and done reason)."""
    action = [9.0, 0.0]
    env = DrivingArenaEnv(CRUISE, action_space="LaneWithContinuousSpeed")
    closing(env)
    obs, _ = env.reset(seed=1)
    steps, reward_sum = 0, 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(np.array(action, np.float32))
        steps += 1
        reward_sum += reward
        if terminated or truncated:
            break
    interface = AgentInterface(action_space=ActionSpace.LaneWithContinuousSpeed)
    result = run_episode(CRUISE, Repeat(action), interface, record_path=tmp_path / "r.npz")
    outcome = result.agents[0]
    assert info["done_reason"] == outcome.reason.value
    assert steps == outcome.steps
    with np.load(tmp_path / "r.npz") as record:
        final_xy = record["x"][0, steps - 1], record["y"][0, steps - 1]
    np.testing.assert_allclose(obs["ego_vehicle_state"]["position"][:2], final_xy, atol=1e-3)
    assert reward_sum != 0.0


def test_collision_terminates_with_events_and_penalty(closing, car_ahead) -> None:
    env = DrivingArenaEnv(car_ahead, action_space="RelativeTargetPose")
    closing(env)
    env.reset(seed=0)
    for _ in range(40):
        obs, reward, terminated, truncated, info = env.step(np.array([2.8, 0.0, 0.0]))
        if terminated or truncated:
            break
    assert terminated and not truncated
    assert info["done_reason"] == "collision"
    assert info["events"]["collisions"] == ["slow"]
    assert obs["events"]["collisions"] == 1
    assert reward < -9.0  # the collision penalty outweighs one step's progress
    assert set(info["scoring_terms"]) >= {"jerk", "speeding", "wrong_way"}
    with pytest.raises(RuntimeError):
        env.step(np.zeros(3))


def test_step_limit_truncates(closing, short_road) -> None:
    env = DrivingArenaEnv(short_road, action_space="Continuous")
    closing(env)
    env.reset(seed=0)
    ends = [env.step(np.array([0.0, 1.0, 0.0]))[2:4] for _ in range(30)]
    assert ends[:-1] == [(False, False)] * 29
    assert ends[-1] == (False, True)


def test_reset_seed_chooses_the_scenario_deterministically(closing) -> None:
    env = DrivingArenaEnv("public", action_space="LaneWithContinuousSpeed")
    closing(env)
    single_agent = {p.name for p in env.scenarios}
    assert all(len(load_scenario(p).missions) == 1 for p in env.scenarios)
    drawn = [env.reset(seed=s)[1]["scenario_id"] for s in (5, 6, 7, 5)]
    assert drawn[0] == drawn[3]
    assert len(set(drawn)) > 1 and set(drawn) <= single_agent


def test_public_is_the_suite_the_settings_name(closing, short_road) -> None:
    settings = env_only(suites={"public_suite_dir": short_road.parent})
    env = DrivingArenaEnv("public", action_space="Continuous", settings=settings)
    closing(env)
    assert env.scenarios == (short_road,)


def test_reward_function_is_replaceable(closing, short_road) -> None:
    seen: list[RewardInput] = []

    def reward_fn(step: RewardInput) -> float:
        seen.append(step)
        return 2.5

    env = DrivingArenaEnv(short_road, action_space="Continuous", reward_fn=reward_fn)
    closing(env)
    env.reset(seed=0)
    assert env.step(np.array([1.0, 0.0, 0.0]))[1] == 2.5
    assert seen[0].agent_id == "Agent_0" and seen[0].done_reason is None
    assert seen[0].current["ego_vehicle_state"]["speed"] > 0.0


def test_async_vector_env_runs_two_simulators() -> None:
    def make(scenario: Path):
        return functools.partial(DrivingArenaEnv, scenario, action_space="LaneWithContinuousSpeed")

    # Not forked from this test process: it may hold other tests' Redis connections, whose
    # after-fork cleanup (kombu's) blocks the child on a socket it shares with the parent.
    envs = gymnasium.vector.AsyncVectorEnv(
        [make(CRUISE), make(PUBLIC / "p000_left_turn_t_low")], context="forkserver"
    )
    try:
        obs, infos = envs.reset(seed=3)
        assert obs["ego_vehicle_state"]["position"].shape == (2, 3)
        assert list(infos["scenario_id"]) == [CRUISE.name, "p000_left_turn_t_low"]
        start = obs["ego_vehicle_state"]["position"].copy()
        for _ in range(10):
            obs, rewards, terminated, _, _ = envs.step(np.tile([8.0, 0.0], (2, 1)))
        assert rewards.shape == (2,) and not terminated.any()
        moved = np.linalg.norm(obs["ego_vehicle_state"]["position"] - start, axis=1)
        assert (moved > 3.0).all()
    finally:
        envs.close()
