"""From scenario outcomes (or a stored results folder) to a :class:`Summary`.

Scores are recomputed from the records every time, so re-scoring a results folder with a new
profile needs no simulation.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from evaluator.runner.manifest import Manifest, SuiteScenario
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.scoring import (
    AgentSummary,
    EpisodeScore,
    ScoringProfile,
    aggregate,
    by_family,
    load_record,
    scenario_metrics,
    score_episode,
    score_without_record,
)
from evaluator.summary import (
    UNCHARGED,
    AgentEntry,
    ProfileRef,
    ScenarioEntry,
    ScenarioStatus,
    Summary,
    read_summary,
)

RECORDS_DIR = "records"
LOGS_DIR = "logs"


def record_path(results_dir: Path, scenario_id: str) -> Path:
    return Path(results_dir) / RECORDS_DIR / f"{scenario_id}.npz"


def summarize(
    outcomes: Iterable[ScenarioOutcome],
    manifest: Manifest,
    profile: ScoringProfile,
    *,
    submission: str,
    running: Iterable[str] = (),
    cache: dict[str, tuple[ScenarioEntry, EpisodeScore | None]] | None = None,
) -> Summary:
    """The summary of ``manifest``'s scenarios: scored from their outcomes' records, ``running``
    for the ids given, ``pending`` for the rest. ``cache`` (scenario id -> scored entry) saves
    re-reading records when a summary is rewritten after every scenario."""
    by_id = {outcome.scenario_id: outcome for outcome in outcomes}
    running = set(running)
    cache = {} if cache is None else cache
    entries, scores = [], []
    for scenario in manifest.scenarios:
        outcome = by_id.get(scenario.id)
        if outcome is None:
            status = ScenarioStatus.running if scenario.id in running else ScenarioStatus.pending
            entries.append(ScenarioEntry(id=scenario.id, family=scenario.family, status=status))
            continue
        if scenario.id not in cache:
            cache[scenario.id] = score_outcome(scenario, outcome, profile)
        entry, score = cache[scenario.id]
        entries.append(entry)
        if score is not None:
            scores.append(score)
    return Summary(
        submission=submission,
        suite=manifest.suite,
        manifest_hash=manifest.hash,
        profile=ProfileRef(**profile.ref),
        complete=all(e.status == ScenarioStatus.done or e.status in UNCHARGED for e in entries),
        metrics=aggregate(scores),
        families=by_family(scores, manifest.family_of),
        uncharged=tuple(e.id for e in entries if e.status in UNCHARGED),
        scenarios=tuple(entries),
    )


def score_results_dir(results_dir: Path, profile: ScoringProfile) -> Summary:
    """Re-score a results folder from its records and ``summary.json``, without simulating."""
    stored = read_summary(results_dir)
    manifest = Manifest(
        suite=stored.suite,
        hash=stored.manifest_hash,
        scenarios=tuple(SuiteScenario(id=e.id, family=e.family) for e in stored.scenarios),
    )
    unfinished = (ScenarioStatus.pending, ScenarioStatus.running)
    outcomes = [
        stored_outcome(entry, results_dir)
        for entry in stored.scenarios
        if entry.status not in unfinished
    ]
    running = [entry.id for entry in stored.scenarios if entry.status == ScenarioStatus.running]
    return summarize(outcomes, manifest, profile, submission=stored.submission, running=running)


def stored_outcome(entry: ScenarioEntry, results_dir: Path) -> ScenarioOutcome:
    path = record_path(results_dir, entry.id)
    return ScenarioOutcome(
        scenario_id=entry.id,
        status=entry.status,
        steps=entry.steps,
        agents=tuple(AgentSummary(**agent.model_dump()) for agent in entry.agents),
        record_path=path if path.exists() else None,
        error=entry.error,
    )


def is_finished(entry: ScenarioEntry, results_dir: Path) -> bool:
    """Done with its record present (or no agent drove a step, so none was written)."""
    if entry.status != ScenarioStatus.done:
        return False
    drove = any(agent.steps for agent in entry.agents)
    return record_path(results_dir, entry.id).exists() or not drove


def score_outcome(
    scenario: SuiteScenario, outcome: ScenarioOutcome, profile: ScoringProfile
) -> tuple[ScenarioEntry, EpisodeScore | None]:
    """The summary entry of a finished scenario and, when charged, its score (from the record).
    Raises :class:`RecordError` on a record that does not follow docs/records.md."""
    if outcome.status != ScenarioStatus.done:
        entry = ScenarioEntry(
            id=scenario.id,
            family=scenario.family,
            status=outcome.status,
            steps=outcome.steps,
            error=outcome.error,
        )
        return entry, None
    if outcome.record_path is not None:
        record = load_record(outcome.record_path)
        score, agents, steps = score_episode(record, profile), record.agents, record.episode_steps
    else:
        agents, steps = outcome.agents, outcome.steps
        score = score_without_record(scenario.id, agents, profile)
    entry = ScenarioEntry(
        id=scenario.id,
        family=scenario.family,
        status=ScenarioStatus.done,
        steps=steps,
        agents=tuple(AgentEntry.of(agent) for agent in agents),
        metrics=scenario_metrics(score),
        terms={name: total / max(score.weight, 1) for name, total in score.term_sums.items()},
    )
    return entry, score
