"""A run's score, computed by the evaluation core from the run's stored scenario outcomes.

The service never scores on its own: it rebuilds the core's :class:`ScenarioOutcome` from each
database row and hands them to :func:`evaluator.runner.score_outcomes`, exactly as ``arena
evaluate`` does with a results folder. A finished run and a re-score take the same path.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from arena.outcome import FINISHED, AgentOutcome, DoneReason, ScenarioStatus
from arena.suite import load_suite
from evaluator.runner import ScenarioOutcome, score_outcomes
from evaluator.scoring import ScoringProfile
from evaluator.summary import Summary
from server.models import EvaluationRun, ScenarioResult


@dataclass(frozen=True)
class RunScore:
    metrics: dict[str, float]
    families: dict[str, dict[str, Any]]  # family -> the four metrics and "scenarios" (count)


def result_values(outcome: ScenarioOutcome, log_tail: str) -> dict[str, Any]:
    """The columns of a :class:`ScenarioResult` row that stores ``outcome``."""
    failed = [agent for agent in outcome.agents if not agent.reached_goal]
    if outcome.status != ScenarioStatus.done:
        reason = str(outcome.status)
    else:
        reason = str(failed[0].reason if failed else DoneReason.reached_goal)
    return {
        "status": outcome.status,
        "reason": reason,
        "steps": outcome.steps,
        "record_path": str(outcome.record_path) if outcome.record_path else None,
        "log_tail": log_tail,
        "detail": {
            "agents": [agent.model_dump(mode="json") for agent in outcome.agents],
            "attempts": outcome.attempts,
            "wall_time_s": outcome.wall_time_s,
            "error": outcome.error,
        },
    }


def stored_outcome(result: ScenarioResult) -> ScenarioOutcome:
    """The core's outcome back from a finished row."""
    path = Path(result.record_path) if result.record_path else None
    return ScenarioOutcome(
        scenario_id=result.scenario_id,
        status=ScenarioStatus(result.status),
        steps=result.steps,
        agents=tuple(AgentOutcome(**agent) for agent in result.detail.get("agents", [])),
        record_path=path if path is not None and path.is_file() else None,
        error=result.detail.get("error"),
    )


def run_summary(run: EvaluationRun, profile: ScoringProfile) -> Summary:
    """The core's summary of a run from its stored outcomes."""
    suite = load_suite(Path(run.suite_dir))
    outcomes = [stored_outcome(r) for r in run.results if r.status in FINISHED]
    running = [r.scenario_id for r in run.results if r.status == ScenarioStatus.running]
    return score_outcomes(
        outcomes, suite, profile, submission=run.submission.file_sha256, running=running
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
    return RunScore(metrics=summary.metrics.model_dump(), families=families)
