"""A run's score, computed by the evaluation core from the run's stored scenario outcomes.

The service never scores on its own: it rebuilds the core's :class:`ScenarioOutcome` from each
database row and hands them to :func:`evaluator.runner.score_outcomes`, exactly as ``arena
evaluate`` does with a results folder. A finished run and a re-score take the same path.
"""

from __future__ import annotations

import contextlib
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from arena.episodes import Episode
from arena.neutralise.storable import storable_json, storable_text
from arena.outcome import FINISHED, AgentOutcome, DoneReason, ScenarioStatus
from arena.suite import load_suite
from evaluator.provenance import Environment, EpisodeRun, Manifest, manifest_of
from evaluator.runner import ScenarioOutcome, score_outcomes
from evaluator.scoring import Interval, ScoringProfile, load_profile
from evaluator.summary import Summary
from server.core.artifacts import ArtifactStore, MissingArtifact
from server.models import EvaluationRun, ScenarioResult


@dataclass(frozen=True)
class RunScore:
    metrics: dict[str, float]
    families: dict[str, dict[str, Any]]  # family -> the four metrics and "scenarios" (count)
    completion_interval: Interval
    samples: dict[str, Any]  # MetricSamples.to_json(): what rank ranges resample


def result_values(
    outcome: ScenarioOutcome, log_tail: str, record_key: str | None
) -> dict[str, Any]:
    """The columns of a :class:`ScenarioResult` row that stores ``outcome`` (whose record the
    worker put in the artifact store under ``record_key``)."""
    failed = [agent for agent in outcome.agents if not agent.reached_goal]
    if outcome.status != ScenarioStatus.done:
        reason = str(outcome.status)
    else:
        reason = str(failed[0].reason if failed else DoneReason.reached_goal)
    return {
        "status": outcome.status,
        "reason": reason,
        "steps": outcome.steps,
        "record_key": record_key,
        "agent_cpu_s": outcome.agent_cpu_s,
        # Agent output: any byte value must record on every database.
        "log_tail": storable_text(log_tail),
        "detail": storable_json(
            {
                "agents": [agent.model_dump(mode="json") for agent in outcome.agents],
                "attempts": outcome.attempts,
                "wall_time_s": outcome.wall_time_s,
                "observed": outcome.observed,
                "error": outcome.error,
                # What the reproducibility manifest pins (evaluator/provenance.py).
                "seed": outcome.seed,
                "environment": (
                    outcome.environment.model_dump() if outcome.environment is not None else None
                ),
            }
        ),
    }


def outcome_from_row(
    result: ScenarioResult, store: ArtifactStore, scratch: Path
) -> ScenarioOutcome:
    """The core's outcome back from a finished row, its record fetched into ``scratch``. A
    record missing from the store leaves the outcome without one (the core then refuses to
    charge a scenario whose agents drove steps)."""
    path = None
    name = Episode(result.scenario_id, result.episode).name
    if result.record_key:
        with contextlib.suppress(MissingArtifact):
            path = store.fetch(result.record_key, scratch / f"{name}.npz")
    return ScenarioOutcome(
        scenario_id=result.scenario_id,
        episode=result.episode,
        status=ScenarioStatus(result.status),
        steps=result.steps,
        agents=tuple(AgentOutcome(**agent) for agent in result.detail.get("agents", [])),
        record_path=path,
        error=result.detail.get("error"),
        seed=result.detail.get("seed"),
        environment=_environment(result),
        agent_cpu_s=result.agent_cpu_s or 0.0,
    )


def _environment(result: ScenarioResult) -> Environment | None:
    stored = result.detail.get("environment")
    return Environment(**stored) if stored else None


def run_manifest(run: EvaluationRun, profile: str, profile_version: str) -> Manifest:
    """The reproducibility manifest of a finished run scored with ``profile``: the suite as it
    is on disk now (the score is written from it), each episode's seed and environment as the
    worker that ran it recorded them."""
    episodes = [
        EpisodeRun(r.scenario_id, r.episode, r.detail.get("seed"), _environment(r))
        for r in run.results
        if r.status in FINISHED
    ]
    training = run.training
    return manifest_of(
        load_suite(Path(run.suite_dir)),
        episodes,
        submission=run.submission.file_sha256,
        model=training.model_sha256 if training is not None else None,
        episodes_per_scenario=run.episodes_per_scenario,
        profile=profile,
        profile_version=profile_version,
    )


def run_summary(run: EvaluationRun, profile: ScoringProfile, store: ArtifactStore) -> Summary:
    """The core's summary of a run from its stored outcomes and records."""
    suite = load_suite(Path(run.suite_dir))
    running = [
        Episode(r.scenario_id, r.episode) for r in run.results if r.status == ScenarioStatus.running
    ]
    with tempfile.TemporaryDirectory(prefix="arena-score-") as scratch:
        outcomes = [
            outcome_from_row(r, store, Path(scratch)) for r in run.results if r.status in FINISHED
        ]
        return score_outcomes(
            outcomes,
            suite,
            profile,
            submission=run.submission.file_sha256,
            episodes_per_scenario=run.episodes_per_scenario,
            running=running,
        )


def run_score(summary: Summary) -> RunScore | None:
    """What the leaderboard stores; None when nothing was charged."""
    if summary.metrics is None:
        return None
    counts: dict[str, int] = {}
    for entry in summary.scenarios:
        if entry.status == ScenarioStatus.done:
            counts[entry.family] = counts.get(entry.family, 0) + 1
    families = {
        family: metrics.model_dump() | {"scenarios": counts[family]}
        for family, metrics in summary.families.items()
    }
    samples = summary.metric_samples(load_profile(summary.profile.name).averaging)
    return RunScore(
        metrics=summary.metrics.model_dump(),
        families=families,
        completion_interval=summary.completion_interval(),
        samples=samples.to_json(),
    )
