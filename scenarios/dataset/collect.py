"""One dataset episode per mission vehicle of a replay scenario: the log replay expert drives it
through the real simulator (isolated process) while we keep what the agent saw and did."""

from __future__ import annotations

import functools
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena.scenario import load_scenario
from scenarios.dataset.features import (
    CRASH_PENALTY,
    GOAL_BONUS,
    ego_pose,
    goal_distance,
    observation_vector,
    pose_action,
)
from scenarios.experts import LogReplayExpert, expert_interface
from scenarios.verify import unsolved_reason
from sim.isolation import run_episode_isolated

CRASH_EVENTS = ("collisions", "off_road")


class RecordingExpert(LogReplayExpert):
    """The log replay expert, keeping per agent and step: observation vector, pose, action,
    distance to goal and the events; written to ``out`` (npz) when the episode closes."""

    def __init__(self, scenario_dir: Path, out: Path) -> None:
        super().__init__(scenario_dir)
        self.out = Path(out)
        self.rows: dict[str, list[tuple]] = {}

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        actions = super().act(obs)
        for agent_id, o in obs.items():
            target = actions[agent_id]
            events = o["events"]
            self.rows.setdefault(agent_id, []).append(
                (
                    observation_vector(o),
                    np.array(ego_pose(o)),
                    pose_action(ego_pose(o), (target[0], target[1], target[2])),
                    goal_distance(o),
                    bool(events["reached_goal"]),
                    bool(any(events[e] for e in CRASH_EVENTS)),
                )
            )
        return actions

    def close(self) -> None:
        arrays = {}
        for agent_id, rows in self.rows.items():
            for name, column in zip(
                ("obs", "pose", "action", "goal_distance", "reached_goal", "crashed"),
                zip(*rows, strict=True),
                strict=True,
            ):
                arrays[f"{agent_id}/{name}"] = np.array(column)
        np.savez(self.out, **arrays)


@dataclass(frozen=True)
class Episode:
    scenario_id: str
    agent_id: str
    observations: np.ndarray  # (n + 1, OBS_SIZE) float32
    poses: np.ndarray  # (n + 1, 3) x [m], y [m], heading [rad] the agent was at
    actions: np.ndarray  # (n, 3) float32
    rewards: np.ndarray  # (n,)
    terminations: np.ndarray  # (n,) bool
    truncations: np.ndarray  # (n,) bool


def collect(scenario_dir: Path) -> tuple[list[Episode], str | None]:
    """The episodes of one non-reactive replay scenario, one per mission vehicle the expert
    brought to its goal, and why it did not bring the others (None when it did).

    The simulator gives no observation after an agent is done, so an episode ends at the last
    observation the agent received: its final transition is *truncated* (or *terminated* when it
    ended in a collision or off the road); the goal bonus applies only to an observed arrival,
    which the expert's episodes (ending at arrival) never contain."""
    scenario = load_scenario(scenario_dir)
    with tempfile.TemporaryDirectory(prefix="arena-dataset-") as tmp:
        out = Path(tmp) / "steps.npz"
        result = run_episode_isolated(
            scenario_dir,
            functools.partial(RecordingExpert, Path(scenario_dir), out),
            expert_interface(scenario_dir),
            record_path=Path(tmp) / "record.npz",
        )
        data = dict(np.load(out)) if out.is_file() else {}
    finished = (
        {a.id for a in result.agents if a.reached_goal} if not result.simulator_error else set()
    )
    episodes = []
    for mission in scenario.missions:
        key = mission.agent_id
        if key not in finished or f"{key}/obs" not in data or len(data[f"{key}/obs"]) < 2:
            continue
        goal_d = data[f"{key}/goal_distance"]
        reached, crashed = data[f"{key}/reached_goal"], data[f"{key}/crashed"]
        rewards = goal_d[:-1] - goal_d[1:] + GOAL_BONUS * reached[1:] - CRASH_PENALTY * crashed[1:]
        n = len(rewards)
        terminations = np.zeros(n, dtype=bool)
        terminations[-1] = bool(crashed[-1])
        episodes.append(
            Episode(
                scenario.id,
                key,
                data[f"{key}/obs"].astype(np.float32),
                data[f"{key}/pose"],
                data[f"{key}/action"][:-1].astype(np.float32),
                rewards.astype(np.float64),
                terminations,
                ~terminations & (np.arange(n) == n - 1),
            )
        )
    return episodes, unsolved_reason(result, "log replay")
