"""The evaluation's CPU budget in a results folder: ``agent_cpu.json`` keeps the CPU time each
finished episode's agent used, so a resumed ``arena evaluate`` keeps counting where the last one
stopped (``--force`` discards it with the results).

Kept out of ``summary.json``, which is deterministic: CPU time is measured, not computed.
"""

from __future__ import annotations

import json
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from arena.cpu_limits import CpuLimits
from arena.files import write_atomically

AGENT_CPU_FILE = "agent_cpu.json"


class AgentCpu(BaseModel):
    """What the agent used of the evaluation's budget [s]."""

    model_config = ConfigDict(frozen=True)

    used_s: float
    budget_s: float
    # episode name (arena.episodes.Episode.name) -> CPU its agent used, from its loading [s]
    episodes: dict[str, float] = {}

    @property
    def over_budget(self) -> bool:
        return self.used_s > self.budget_s


class CpuLedger:
    """The running total of one results folder, under ``limits``' evaluation budget. Not
    thread-safe: the results folder calls it under its own lock."""

    def __init__(self, out_dir: Path, limits: CpuLimits) -> None:
        self.path = Path(out_dir) / AGENT_CPU_FILE
        self.limits = limits
        previous = read_agent_cpu(out_dir)
        self.episodes: dict[str, float] = dict(previous.episodes) if previous else {}

    @property
    def used_s(self) -> float:
        return sum(self.episodes.values())

    @property
    def over_budget(self) -> bool:
        return self.limits.over_budget(self.used_s)

    def charge(self, episode: str, seconds: float) -> None:
        """``episode`` finished having used ``seconds``; an episode run again replaces its
        earlier figure (it is counted once)."""
        self.episodes[episode] = round(seconds, 3)

    def message(self) -> str:
        return self.limits.budget_exceeded(self.used_s, len(self.episodes))

    def write(self) -> AgentCpu:
        state = AgentCpu(
            used_s=round(self.used_s, 3),
            budget_s=self.limits.evaluation_s,
            episodes=dict(sorted(self.episodes.items())),
        )
        write_atomically(self.path, json.dumps(state.model_dump(), indent=2) + "\n")
        return state


def read_agent_cpu(out_dir: Path) -> AgentCpu | None:
    """The folder's ``agent_cpu.json``; None when there is none."""
    path = Path(out_dir) / AGENT_CPU_FILE
    if not path.exists():
        return None
    return AgentCpu.model_validate_json(path.read_text())
