"""The experts of the solvability rule: a log-replay agent for replays (drives each removed
vehicle's own recorded trajectory with TargetPose actions) and the reference planner for reactive
scenarios. Both are plain :class:`sim.agent.Agent` s, built by picklable factories for the isolated
episode runner."""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import yaml

from arena.examples import example_dir
from arena.scenario import load_scenario
from scenarios.recorded.builder import EXPERT_FILE
from sim.interface import ActionSpace, AgentInterface
from sim.trajectories import Trajectory, read_trajectories


class LogReplayExpert:
    """Moves every agent to its recorded pose of the next step."""

    def __init__(self, scenario_dir: Path) -> None:
        scenario = load_scenario(scenario_dir)
        self.start_step = {m.agent_id: m.start_step for m in scenario.missions}
        self.dt = scenario.step_length
        self.paths: dict[str, Trajectory] = read_trajectories(Path(scenario_dir) / EXPERT_FILE)

    def reset(self) -> None:
        pass

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        actions = {}
        for agent_id, o in obs.items():
            path = self.paths[agent_id]
            frame = min(int(o["step_count"]) + 1 - self.start_step[agent_id], len(path.x) - 1)
            frame = max(frame, 0)
            actions[agent_id] = [
                float(path.x[frame]),
                float(path.y[frame]),
                float(path.heading[frame]),
                self.dt,
            ]
        return actions

    def close(self) -> None:
        pass


class PlannerAgent:
    """The reference planner of ``examples/planner`` as an in-process agent."""

    def __init__(self) -> None:
        spec = importlib.util.spec_from_file_location(
            "arena_reference_planner", example_dir("planner") / "policy.py"
        )
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        self._policy_class = module.Policy
        self.policy = module.Policy()

    def reset(self) -> None:
        self.policy = self._policy_class()

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return self.policy.act(obs)

    def close(self) -> None:
        pass


def uses_log_replay(scenario_dir: Path) -> bool:
    """Non-reactive replays are verified by log replay; everything reactive (the replay with a
    reactive bubble included: its traffic no longer follows the recording) by the planner."""
    return (Path(scenario_dir) / EXPERT_FILE).exists() and not load_scenario(scenario_dir).reactive


def expert_factory(scenario_dir: Path):
    """A picklable zero-argument factory of the expert for ``scenario_dir``."""
    if uses_log_replay(scenario_dir):
        return functools.partial(LogReplayExpert, Path(scenario_dir))
    return PlannerAgent


def expert_interface(scenario_dir: Path) -> AgentInterface:
    if uses_log_replay(scenario_dir):
        return AgentInterface(action_space=ActionSpace.TargetPose)
    return planner_interface()


def planner_interface() -> AgentInterface:
    data = yaml.safe_load((example_dir("planner") / "agent.yaml").read_text()) or {}
    return AgentInterface(**data)
