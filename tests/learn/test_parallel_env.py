"""The PettingZoo environment: API conformance and every mission agent acting at once."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from learn.parallel_env import DrivingArenaParallelEnv
from tests.learn.conftest import PUBLIC

TWO_AGENTS = PUBLIC / "p019_cruise_2lane_low_2agents"
THREE_AGENTS = PUBLIC / "p020_cruise_3lane_curve_low_3agents"


def test_passes_pettingzoos_parallel_api_test(closing) -> None:
    env = DrivingArenaParallelEnv(TWO_AGENTS, action_space="LaneWithContinuousSpeed")
    closing(env)
    parallel_api_test(env, num_cycles=60)


class OneAgent(gymnasium.Env):
    """One agent of the parallel env, present from the first step, seen as a Gymnasium env (the
    others keep their lane): the shape in which SB3 checks it."""

    def __init__(self, env: DrivingArenaParallelEnv, agent: str) -> None:
        self.env, self.agent = env, agent
        self.observation_space = env.observation_space(agent)
        self.action_space = env.action_space(agent)

    def reset(self, *, seed=None, options=None):
        obs, infos = self.env.reset(seed=seed, options=options)
        return obs[self.agent], infos[self.agent]

    def step(self, action):
        actions = {a: np.array([8.0, 0.0], np.float32) for a in self.env.agents}
        actions[self.agent] = action
        obs, rewards, terminations, truncations, infos = self.env.step(actions)
        a = self.agent
        return obs[a], rewards[a], terminations[a], truncations[a], infos[a]


def test_each_agent_passes_stable_baselines3s_env_checker(closing) -> None:
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = DrivingArenaParallelEnv(TWO_AGENTS, action_space="LaneWithContinuousSpeed")
    closing(env)
    env.reset(seed=0)
    for agent in env.agents:  # those present from the start (a Gymnasium env has one from reset)
        with pytest.warns(UserWarning, match="Nested observation spaces"):
            env_checker.check_env(OneAgent(env, agent))


@pytest.mark.slow
def test_three_agents_act_at_once_joining_and_leaving(closing) -> None:
    env = DrivingArenaParallelEnv(THREE_AGENTS, action_space="LaneWithContinuousSpeed")
    closing(env)
    obs, _ = env.reset(seed=0)
    assert env.possible_agents == ["Agent_0", "Agent_1", "Agent_2"]
    assert env.agents == sorted(obs) and env.agents  # those that start at step 0
    seen, finished = set(env.agents), {}
    for _ in range(1000):
        actions = {a: np.array([8.0, 0.0]) for a in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)
        assert set(obs) == set(rewards) == set(terminations) == set(infos)
        for agent in obs:
            assert env.observation_space(agent).contains(obs[agent])
            if terminations[agent] or truncations[agent]:
                finished[agent] = infos[agent]["done_reason"]
                assert agent not in env.agents
        seen |= set(env.agents)
        if not env.agents:
            break
    assert seen == set(finished) == {"Agent_0", "Agent_1", "Agent_2"}
    assert all(reason is not None for reason in finished.values())
