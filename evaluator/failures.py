"""Failure messages that explain themselves: one wording of how an agent's episode ended, the
tracebacks of a scenario's log, identical tracebacks grouped, and an agent that never started.

Used by ``arena evaluate`` (terminal) and the results folder's logs, so the step numbers and
wording agree wherever a failure is shown.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

from arena.outcome import Verdict, episode_verdict

# An agent that ends with one of these before driving a single step never got going.
STARTUP_FAULTS = frozenset({"agent_error", "init_timeout", "memory_limit", "agent_exited"})
# How many scenarios in a row must show the agent failing to start before a run stops early.
FAIL_FAST_AFTER = 2

_TRACEBACK = re.compile(r"^Traceback \(most recent call last\):\n(?:[ \t].*\n|\n)*?\S.*$", re.M)


class AgentEnd(Protocol):
    id: str
    reason: str
    steps: int  # agent-steps driven
    done_step: int  # episode step (1-based) at which the agent was done


def describe_end(agent: AgentEnd) -> str:
    """``"Agent_0 invalid_action at step 1 (0 steps driven)"``: the one wording everywhere."""
    return f"{agent.id} {agent.reason} at step {agent.done_step} ({agent.steps} steps driven)"


def tracebacks(log: str) -> list[str]:
    """The Python tracebacks in a log, in order (each from its header to the exception line)."""
    return [match.group(0).strip() for match in _TRACEBACK.finditer(log)]


def never_started(agents: Sequence[AgentEnd]) -> bool:
    """Every agent of the scenario failed as a program before driving a single step."""
    return bool(agents) and all(a.steps == 0 and a.reason in STARTUP_FAULTS for a in agents)


def is_agent_fault(agents: Iterable[AgentEnd]) -> bool:
    """The episode's verdict is the team's program (:func:`arena.outcome.verdict`): `arena
    evaluate` exits non-zero when any episode's is."""
    return episode_verdict(a.reason for a in agents) is Verdict.agent


@dataclass(frozen=True)
class Group:
    """One failure text and the scenarios that produced it."""

    text: str
    scenarios: tuple[str, ...]


def group_identical(texts: Iterable[tuple[str, str]]) -> list[Group]:
    """(scenario id, text) pairs -> one group per distinct text, in first-seen order."""
    groups: dict[str, list[str]] = {}
    for scenario_id, text in texts:
        groups.setdefault(text, []).append(scenario_id)
    return [Group(text, tuple(ids)) for text, ids in groups.items()]


def failure_block(log: str) -> str:
    """The failure lines of a scenario log's last attempt: how each agent ended and the detail
    the outcome carries (e.g. what was wrong with an action), without the agent's own output."""
    blocks = re.split(r"^--- ", log, flags=re.M)
    attempts = [b for b in blocks if b.startswith("attempt ")]
    if not attempts:
        return log.strip()[:2000]
    lines = attempts[-1].splitlines()[1:]  # drop the "attempt k: id" header
    return "\n".join(line for line in lines if line.strip()).strip()


def failure_texts(log: str, *, every: bool) -> list[str]:
    """The tracebacks of a scenario log (the first one, or ``every`` one); the failure lines when
    it holds none (a bad action, a timeout)."""
    found = tracebacks(log)
    if not found:
        block = failure_block(log)
        return [block] if block else []
    return found if every else found[:1]


def startup_error(log: str) -> str:
    """What to show for an agent that could not start: its last traceback, or the failure lines
    when there is none (a timeout)."""
    found = tracebacks(log)
    return found[-1] if found else failure_block(log)
