"""``summary.json``: the results of one submission on one scenario set (``docs/summary.md``).

Only deterministic content goes here (no wall times), so evaluating the same submission twice
gives byte-identical files.
"""

from __future__ import annotations

import json
import os
from enum import StrEnum
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from evaluator.scoring import Metrics

SUMMARY_FILE = "summary.json"


class ScenarioStatus(StrEnum):
    pending = "pending"  # selected, not started
    running = "running"  # started; left so if the runner died mid-way
    done = "done"  # simulated and scored (agent failures included: they are charged)
    simulator_error = "simulator_error"  # SUMO failed twice: ours, not charged
    evaluator_error = "evaluator_error"  # the sandbox or runner failed: ours, not charged


UNCHARGED = frozenset({ScenarioStatus.simulator_error, ScenarioStatus.evaluator_error})


class Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class AgentEntry(Frozen):
    id: str
    reached_goal: bool
    reason: str  # a sim.agent.DoneReason value
    steps: int  # agent-steps driven
    done_step: int  # episode step (1-based) at which the agent was done

    @classmethod
    def of(cls, agent: object) -> AgentEntry:
        """The summary fields of a scoring ``AgentSummary`` (which also carries positions)."""
        return cls(**{name: getattr(agent, name) for name in cls.model_fields})


class ScenarioEntry(Frozen):
    id: str
    family: str
    status: ScenarioStatus
    steps: int = 0  # episode steps simulated
    agents: tuple[AgentEntry, ...] = ()
    metrics: Metrics | None = None  # this scenario alone
    terms: dict[str, float] | None = None  # mean of each metric term over its agent-steps
    error: str | None = None  # why a scenario was not charged


class ProfileRef(Frozen):
    name: str
    version: int


class Summary(Frozen):
    submission: str  # sha256 of the submission
    suite: str
    manifest_hash: str  # sha256 of the suite's manifest.json
    profile: ProfileRef
    complete: bool  # every selected scenario is finished (done or uncharged)
    metrics: Metrics | None  # over the charged scenarios; None when there are none
    families: dict[str, Metrics]
    uncharged: tuple[str, ...]  # scenario ids excluded from N (our failures)
    scenarios: tuple[ScenarioEntry, ...]


def write_summary(summary: Summary, results_dir: Path) -> Path:
    """Atomic: a reader (or a crash) never sees a half-written file."""
    path = Path(results_dir) / SUMMARY_FILE
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(summary.model_dump(mode="json"), indent=2) + "\n")
    os.replace(tmp, path)
    return path


def read_summary(results_dir: Path) -> Summary:
    return Summary.model_validate_json((Path(results_dir) / SUMMARY_FILE).read_text())
