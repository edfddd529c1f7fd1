"""``summary.json``: the results of one submission on one scenario set (``docs/summary.md``).

Only deterministic content goes here (no wall times), so evaluating the same submission twice
gives byte-identical files.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict

from arena.files import write_atomically
from arena.outcome import AgentOutcome, ScenarioStatus
from evaluator.provenance import Manifest
from evaluator.scoring import Interval, Metrics, bootstrap_interval
from evaluator.scoring.profile import Averaging
from evaluator.scoring.significance import MetricSamples

SUMMARY_FILE = "summary.json"


class Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class EpisodeEntry(Frozen):
    """One episode of a scenario run several times (``Summary.episodes_per_scenario`` > 1)."""

    index: int  # 0 is the scenario's own traffic seed (arena.episodes)
    status: ScenarioStatus
    steps: int = 0
    agents: tuple[AgentOutcome, ...] = ()
    metrics: Metrics | None = None  # this episode alone
    error: str | None = None


class ScenarioEntry(Frozen):
    id: str
    family: str
    status: ScenarioStatus
    steps: int = 0  # episode steps simulated (over all its episodes)
    agents: tuple[AgentOutcome, ...] = ()  # run once only; else in each of ``episodes``
    # This scenario alone; run several times, the mean over its episodes.
    metrics: Metrics | None = None
    terms: dict[str, float] | None = None  # mean of each metric term over its agent-steps
    error: str | None = None  # why a scenario was not charged
    # Only for a scenario run several times: each episode, in order.
    episodes: tuple[EpisodeEntry, ...] | None = None


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
    episodes_per_scenario: int = 1  # of each reactive scenario (arena.episodes)
    # What the results depend on (evaluator/provenance.py); written by `arena evaluate`.
    manifest: Manifest | None = None

    def to_dict(self) -> dict:
        """The JSON shape: with one episode per scenario, exactly the shape from before episodes
        existed (no ``episodes_per_scenario``, no per-scenario ``episodes``); ``manifest`` only
        when there is one."""
        data = self.model_dump(mode="json")
        if self.episodes_per_scenario == 1:
            del data["episodes_per_scenario"]
        if self.manifest is None:
            del data["manifest"]
        for entry in data["scenarios"]:
            if entry["episodes"] is None:
                del entry["episodes"]
        return data

    def completion_samples(self) -> list[list[float]]:
        """Each charged scenario's completion error in each of its episodes: what the
        completion interval resamples."""
        return [
            [e.metrics.completion for e in entry.episodes]
            if entry.episodes
            else [entry.metrics.completion]
            for entry in self.scenarios
            if entry.status == ScenarioStatus.done and entry.metrics is not None
        ]

    def completion_interval(self) -> Interval | None:
        """The 95% bootstrap interval of ``metrics.completion`` (docs/scoring.md); None when no
        scenario was charged."""
        samples = self.completion_samples()
        return bootstrap_interval(samples) if samples else None

    def metric_samples(self, averaging: Averaging) -> MetricSamples | None:
        """Each charged scenario's values in each of its episodes, what rank ranges resample
        (``docs/scoring.md``); None when no scenario was charged. Humanness and rules come back
        as sums over what the profile's ``averaging`` weighs (agent-steps, or the agent-episodes
        that drove), so the suite's ratio of sums is rebuilt exactly."""
        scenarios = {}
        for entry in self.scenarios:
            if entry.status != ScenarioStatus.done or entry.metrics is None:
                continue
            rows = []
            for episode in entry.episodes or (entry,):
                steps = [agent.steps for agent in episode.agents]
                weight = sum(steps) if averaging is Averaging.agent_step else sum(map(bool, steps))
                metrics = episode.metrics
                rows.append(
                    [
                        metrics.completion,
                        metrics.time,
                        (metrics.humanness or 0.0) * weight,
                        (metrics.rules or 0.0) * weight,
                        weight,
                    ]
                )
            scenarios[entry.id] = np.array(rows, dtype=float)
        return MetricSamples(suite=self.manifest_hash, scenarios=scenarios) if scenarios else None


def write_summary(summary: Summary, results_dir: Path) -> Path:
    """Atomic: a reader (or a crash) never sees a half-written file."""
    return write_atomically(
        Path(results_dir) / SUMMARY_FILE, json.dumps(summary.to_dict(), indent=2) + "\n"
    )


def read_summary(results_dir: Path) -> Summary:
    return Summary.model_validate_json((Path(results_dir) / SUMMARY_FILE).read_text())
