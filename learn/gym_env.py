"""``arena/DrivingArena-v0``: one mission agent on the arena's simulator, as a Gymnasium env."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from arena.config import Settings
from evaluator.scoring import DEFAULT_PROFILE
from learn.protocol import Config, Reply, Simulator, SimulatorMode, check_simulator_mode
from learn.reward import RewardFn, RewardInput, default_reward
from learn.scenarios import env_scenario_dirs
from learn.simulators import open_simulator
from learn.spaces import ENV_DEFAULT_ACTION_SPACE, action_space, observation_space
from sim.interface import AgentInterface

MAX_STEPS_REASON = "max_episode_steps"


class EpisodeState:
    """What an environment remembers of the running episode, per agent."""

    def __init__(self, reply: Reply) -> None:
        self.scenario_id = reply.scenario_id
        self.last_obs: dict[str, dict] = dict(reply.observations)


def step_outcome(
    agent_id: str, reply: Reply, state: EpisodeState, reward_fn: RewardFn
) -> tuple[dict, float, bool, bool, dict]:
    """(observation, reward, terminated, truncated, info) of one agent after a step.

    ``terminated`` when the agent's episode ended for any reason but the step limit (goal,
    collision, off road, invalid action), ``truncated`` at the step limit."""
    previous = state.last_obs[agent_id]
    reason = reply.finished.get(agent_id)
    # A finished agent has no terminal observation only when it did not drive (invalid action).
    obs = reply.observations[agent_id] if reason is None else reply.terminal.get(agent_id, previous)
    events = reply.events.get(agent_id, {})
    terms = reply.terms.get(agent_id, {})
    reward = reward_fn(RewardInput(agent_id, previous, obs, events, reason, terms))
    state.last_obs[agent_id] = obs
    info = {
        "scenario_id": reply.scenario_id,
        "step": reply.step,
        "events": events,
        "done_reason": reason,
        "scoring_terms": terms,
    }
    ids = reply.ids.get(agent_id)
    if ids is not None:
        info["ids"] = ids
    terminated = reason is not None and reason != MAX_STEPS_REASON
    truncated = reason == MAX_STEPS_REASON
    return obs, float(reward), terminated, truncated, info


class DrivingArenaEnv(gym.Env):
    """One mission agent, episodes drawn from single-agent scenarios of a suite.

    Keyword arguments: ``suite`` (``public``, a built suite folder or a scenario folder),
    ``scenario`` (an id or folder: always that one; default: one drawn per ``reset(seed=...)``,
    deterministic for a seed), ``action_space`` and every other ``agent.yaml`` option
    (``top_down_rgb=True``, ``img_pixels=...``, ``max_neighbours=...``), ``reward_fn``
    (replaces :func:`learn.reward.default_reward`), ``profile`` (the
    scoring profile whose terms go into ``info``) and ``traffic_seed`` (``"scenario"``: the
    scenario's own seed, as evaluation uses; ``"random"``: drawn from the reset seed) and
    ``simulator`` (where the simulator runs: ``"auto"``, ``"in_process"`` or ``"subprocess"``,
    see :func:`learn.simulators.open_simulator`) and ``render_mode`` (``"rgb_array"``:
    ``render()`` returns a top-down picture around the agent with its goal, :mod:`learn.render`;
    for ``gymnasium.wrappers.RecordVideo``) and ``settings`` (where the suites ``public`` and
    ``hidden`` are; default: read from the environment, since ``gymnasium.make`` has none to
    hand).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012 - gymnasium's

    def __init__(
        self,
        suite: str | Path = "public",
        scenario: str | Path | None = None,
        *,
        action_space: str = ENV_DEFAULT_ACTION_SPACE,
        reward_fn: RewardFn | None = None,
        profile: str | None = None,
        traffic_seed: str = "scenario",
        simulator: SimulatorMode = "auto",
        render_mode: str | None = None,
        settings: Settings | None = None,
        **interface_options: Any,
    ) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode is 'rgb_array' or None, not {render_mode!r}")
        self.render_mode = render_mode
        self.interface = AgentInterface(action_space=action_space, **interface_options)
        self.scenarios = env_scenario_dirs(suite, scenario, settings, agents=(1, 1))
        self.observation_space = observation_space(self.interface)
        self.action_space = _action_space(self.interface)
        self.reward_fn = reward_fn or default_reward
        if traffic_seed not in ("scenario", "random"):
            raise ValueError("traffic_seed is 'scenario' or 'random'")
        self.traffic_seed = traffic_seed
        self._config = Config(
            self.interface, _profile_name(profile), render=render_mode == "rgb_array"
        )
        self._picture: np.ndarray | None = None
        check_simulator_mode(simulator)
        self._simulator_mode = simulator
        self._simulator: Simulator | None = None  # opened at the first reset
        self._state: EpisodeState | None = None
        self._agent_id = ""

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        reply = start_episode(self, options)
        self._picture = reply.picture
        self._agent_id, obs = next(iter(reply.observations.items()))
        self._state = EpisodeState(reply)
        info = {
            "scenario_id": reply.scenario_id,
            "step": reply.step,
            "ids": reply.ids[self._agent_id],
        }
        return obs, info

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        if self._state is None or self._simulator is None:
            raise RuntimeError("reset() before step()")
        reply = self._simulator.step({self._agent_id: np.asarray(action).tolist()})
        self._picture = reply.picture
        out = step_outcome(self._agent_id, reply, self._state, self.reward_fn)
        if out[2] or out[3]:
            self._state = None  # stepping on needs a reset
        return out

    def render(self) -> np.ndarray | None:
        """The top-down picture (H, W, 3) uint8 of the last reset or step, with
        ``render_mode="rgb_array"``; None otherwise."""
        if self.render_mode != "rgb_array" or self._picture is None:
            return None
        return np.asarray(self._picture).copy()

    def close(self) -> None:
        if self._simulator is not None:
            self._simulator.close()
            self._simulator = None
        super().close()


def start_episode(env: Any, options: dict | None) -> Reply:
    """Reset ``env``'s simulator (opening it if needed) on the scenario ``options`` names or one
    drawn from ``env.np_random``."""
    folder = (options or {}).get("scenario")
    if folder is None:
        folder = env.scenarios[int(env.np_random.integers(len(env.scenarios)))]
    sim_seed = None
    if env.traffic_seed == "random":
        sim_seed = int(env.np_random.integers(2**31 - 1))
    if env._simulator is None:
        env._simulator = open_simulator(env._config, env._simulator_mode)
    reply = env._simulator.reset(str(folder), sim_seed)
    if not reply.observations:
        raise RuntimeError(f"{reply.scenario_id}: the episode ended before any agent entered")
    return reply


def _action_space(interface: AgentInterface) -> gym.spaces.Box:
    return action_space(interface.action_space)


def _profile_name(profile: str | None) -> str:
    return profile or DEFAULT_PROFILE
