"""How an episode and a scenario ended: the vocabulary every layer shares.

The simulator produces :class:`AgentOutcome`, the episode record stores it, scoring reads it back,
``summary.json`` and the service's database keep it: one type, so the copies cannot drift.
:class:`ScenarioStatus` is the one status vocabulary of a scenario in an evaluation, locally and in
the service, and :data:`UNCHARGED` the one charging rule: those scenarios are ours, never the
participant's.
"""

from __future__ import annotations

from enum import StrEnum

from pydantic import BaseModel, ConfigDict


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


class AgentOutcome(BaseModel):
    """One mission agent's end of an episode."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    id: str
    reached_goal: bool
    reason: DoneReason
    steps: int  # agent-steps driven (rows in the record)
    done_step: int  # episode step (1-based) at which the agent was done


class ScenarioStatus(StrEnum):
    """A scenario of one evaluation, locally (``summary.json``) and in the service's database."""

    pending = "pending"  # selected, not started
    running = "running"  # started; left so if the runner died mid-way
    done = "done"  # simulated and scored (agent failures included: they are charged)
    simulator_error = "simulator_error"  # SUMO failed on every attempt: ours, not charged
    evaluator_error = "evaluator_error"  # the sandbox, runner or record failed: ours, not charged


UNCHARGED = frozenset({ScenarioStatus.simulator_error, ScenarioStatus.evaluator_error})
FINISHED = frozenset({ScenarioStatus.done, *UNCHARGED})
