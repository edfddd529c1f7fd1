"""The arena's simulator as a PettingZoo ``ParallelEnv``: every mission agent of a scenario (1-3)
acts at once, as in evaluation."""

from __future__ import annotations

from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from arena.config import Settings
from arena.scenario import load_scenario
from learn.gym_env import EpisodeState, _profile_name, start_episode, step_outcome
from learn.protocol import Config, Simulator, SimulatorMode, check_simulator_mode
from learn.reward import RewardFn, default_reward
from learn.scenarios import env_scenario_dirs
from learn.spaces import ENV_DEFAULT_ACTION_SPACE, action_space, observation_space
from sim.interface import AgentInterface


class DrivingArenaParallelEnv(ParallelEnv):
    """Mission agents of scenarios with 1 to 3 of them; same keyword arguments as
    :class:`learn.gym_env.DrivingArenaEnv` plus ``agents=(low, high)`` to choose scenarios by
    their number of agents. An agent leaves ``agents`` after the step that ended it (its final
    observation, reward and ``terminations``/``truncations`` flag come with that step); agents
    that start later join ``agents`` when they enter."""

    metadata = {"name": "driving_arena_v0", "render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        suite: str | Path = "public",
        scenario: str | Path | None = None,
        *,
        agents: tuple[int, int] = (1, 3),
        action_space: str = ENV_DEFAULT_ACTION_SPACE,
        reward_fn: RewardFn | None = None,
        profile: str | None = None,
        traffic_seed: str = "scenario",
        simulator: SimulatorMode = "auto",
        settings: Settings | None = None,
        **interface_options: Any,
    ) -> None:
        self.interface = AgentInterface(action_space=action_space, **interface_options)
        self.scenarios = env_scenario_dirs(suite, scenario, settings, agents=agents)
        ids = {m.agent_id for folder in self.scenarios for m in load_scenario(folder).missions}
        self.possible_agents = sorted(ids)
        self.agents: list[str] = []
        self.reward_fn = reward_fn or default_reward
        self.traffic_seed = traffic_seed
        self.np_random, _ = seeding.np_random(None)
        self._config = Config(self.interface, _profile_name(profile))
        check_simulator_mode(simulator)
        self._simulator_mode = simulator
        self._simulator: Simulator | None = None
        self._state: EpisodeState | None = None

    @cached_property
    def _observation_space(self):
        return observation_space(self.interface)

    @cached_property
    def _action_space(self):
        return action_space(self.interface.action_space)

    def observation_space(self, agent: str):
        return self._observation_space

    def action_space(self, agent: str):
        return self._action_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self.np_random, _ = seeding.np_random(seed)
        reply = start_episode(self, options)
        self._state = EpisodeState(reply)
        self.agents = sorted(reply.observations)
        infos = {
            a: {"scenario_id": reply.scenario_id, "step": reply.step, "ids": reply.ids[a]}
            for a in self.agents
        }
        return dict(reply.observations), infos

    def step(self, actions: dict[str, np.ndarray]):
        if self._state is None or self._simulator is None:
            raise RuntimeError("reset() before step()")
        sent = {a: np.asarray(actions[a]).tolist() for a in self.agents if a in actions}
        reply = self._simulator.step(sent)
        obs, rewards, terminations, truncations, infos = {}, {}, {}, {}, {}
        for agent in self.agents:
            o, r, term, trunc, info = step_outcome(agent, reply, self._state, self.reward_fn)
            obs[agent], rewards[agent] = o, r
            terminations[agent], truncations[agent], infos[agent] = term, trunc, info
        for agent, o in reply.observations.items():  # agents entering on this step
            if agent not in obs:
                self._state.last_obs[agent] = o
                obs[agent], rewards[agent] = o, 0.0
                terminations[agent] = truncations[agent] = False
                infos[agent] = {"scenario_id": reply.scenario_id, "step": reply.step}
        self.agents = sorted(reply.observations)
        return obs, rewards, terminations, truncations, infos

    def close(self) -> None:
        if self._simulator is not None:
            self._simulator.close()
            self._simulator = None
