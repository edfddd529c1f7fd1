"""What the simulator needs from whatever drives the mission vehicles.

The evaluator's sandboxed agent handles and in-process test policies both satisfy :class:`Agent`.
A failure of the agent itself (not of one action) is raised as :class:`AgentFailed`; the episode
then ends for every mission vehicle with that reason, keeping the steps already driven.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Any, Protocol

Observation = dict[str, Any]
Action = list[float]


class DoneReason(StrEnum):
    """Why a mission agent's episode ended. Only ``reached_goal`` is a success."""

    reached_goal = "reached_goal"
    collision = "collision"
    off_road = "off_road"
    max_episode_steps = "max_episode_steps"
    invalid_action = "invalid_action"
    agent_error = "agent_error"
    init_timeout = "init_timeout"
    step_timeout = "step_timeout"
    episode_timeout = "episode_timeout"
    memory_limit = "memory_limit"
    agent_exited = "agent_exited"
    sandbox_error = "sandbox_error"
    # Our fault, not the participant's: never charged to a submission.
    simulator_error = "simulator_error"


class AgentFailed(Exception):
    """The agent as a whole failed (crashed, timed out, died); not a single bad action."""

    def __init__(self, reason: DoneReason, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else str(reason))
        self.reason = reason
        self.detail = detail


class Agent(Protocol):
    def reset(self) -> None:
        """A new episode starts."""

    def act(self, obs: dict[str, Observation]) -> dict[str, Any]:
        """One action per agent id in ``obs``. May raise :class:`AgentFailed`."""

    def close(self) -> None:
        """Release the agent (process, container)."""


class SomeAgentsFailed(Exception):
    """The agent answered for some of its mission vehicles and raised for the others: those end
    with ``agent_error`` (``failed``: id -> detail), the rest drive on with ``actions``."""

    def __init__(self, actions: dict[str, Any], failed: dict[str, str]) -> None:
        super().__init__(f"agent_error for {', '.join(sorted(failed))}")
        self.actions = actions
        self.failed = failed
