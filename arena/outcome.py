"""How an episode and a scenario ended: the vocabulary every layer shares.

The simulator produces :class:`AgentOutcome`, the episode record stores it, scoring reads it back,
``summary.json`` and the service's database keep it: one type, so the copies cannot drift.
:class:`ScenarioStatus` is the one status vocabulary of a scenario in an evaluation, locally and in
the service. :func:`verdict` is the one rule of whose an episode's end is (the team's program,
its driving, or ours: docs/protocol.md, "Whose failure it is"), and :data:`UNCHARGED` the
statuses of the episodes it calls ours, never charged to the participant.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
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


class Verdict(StrEnum):
    """Whose an episode's end is."""

    agent = "agent"  # the team's program failed: charged, shown as its failure
    driving = "driving"  # it ended by driving (goal, collision, off road) or the step limit
    ours = "ours"  # our side failed: not charged, run again


class Process(StrEnum):
    """Which process failed, as our side saw it (never as the agent says)."""

    team = "team"  # the team's sandboxed process (the runtime in it, once it said hello)
    team_files = "team_files"  # a process of ours reading the team's files (agent.yaml, the zip)
    ours = "ours"  # the simulator's process, the worker, the sandbox machinery, the record


@dataclass(frozen=True)
class Facts:
    """What decides a verdict: facts our side controls."""

    failed: Process | None  # None: nothing failed
    # Anything of the team's had been loaded (imports included): its runtime said hello, the
    # last thing it does before reading the submission, or a process of ours read its files.
    team_loaded: bool
    # The team's process was running and within its limits when ours failed.
    team_healthy: bool = True


def verdict(facts: Facts) -> Verdict:
    """The rule: an end with no failure is the driving's; a failure before anything of the
    team's was loaded is ours; after, it is the team's unless our own process failed while
    the team's was healthy."""
    if facts.failed is None:
        return Verdict.driving
    if not facts.team_loaded:
        return Verdict.ours
    if facts.failed is Process.ours and facts.team_healthy:
        return Verdict.ours
    return Verdict.agent


# Reasons that say the team's process failed as a program (not a driving mistake), after its
# runtime said hello.
AGENT_FAULTS = frozenset(
    {
        DoneReason.invalid_action,
        DoneReason.agent_error,
        DoneReason.init_timeout,
        DoneReason.step_timeout,
        DoneReason.episode_timeout,
        DoneReason.memory_limit,
        DoneReason.agent_exited,
    }
)


def episode_facts(reasons: Iterable[DoneReason | str], *, simulator_failed: bool) -> Facts:
    """The facts of an episode from how its agents ended (reasons our side assigned) and whether
    the simulator's process failed. ``sandbox_error`` is the one reason our side gives a sandbox
    that ended by our side's doing: before its runtime said hello (nothing of the team's was
    loaded), or stopped from outside, as the daemon that runs it says."""
    reasons = {DoneReason(r) for r in reasons}
    team_failed = bool(reasons & AGENT_FAULTS)
    if simulator_failed:
        return Facts(Process.ours, team_loaded=True, team_healthy=not team_failed)
    if team_failed:
        return Facts(Process.team, team_loaded=True)
    if DoneReason.sandbox_error in reasons:
        return Facts(Process.team, team_loaded=False)
    return Facts(None, team_loaded=True)


def episode_verdict(reasons: Iterable[DoneReason | str], *, simulator_failed: bool = False):
    """:func:`verdict` of an episode (see :func:`episode_facts`)."""
    return verdict(episode_facts(reasons, simulator_failed=simulator_failed))
