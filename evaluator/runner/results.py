"""The evaluation core's scoring half: scenario outcomes -> :class:`Summary`.

``arena evaluate``, ``arena score`` and the service's workers all go through
:func:`score_outcomes`, so a local evaluation and the service can never disagree. Scores are
recomputed from the records every time, so re-scoring with a new profile needs no simulation.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

from arena.errors import RecordError
from arena.outcome import FINISHED, UNCHARGED, ScenarioStatus
from arena.record_format import RECORD_SUFFIX
from arena.suite import ManifestEntry, Suite, SuiteManifest
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.scoring import (
    EpisodeScore,
    ScoringProfile,
    aggregate,
    by_family,
    load_record,
    scenario_metrics,
    score_episode,
    score_without_record,
)
from evaluator.summary import ProfileRef, ScenarioEntry, Summary, read_summary

RECORDS_DIR = "records"
LOGS_DIR = "logs"

ScoredEntry = tuple[ScenarioEntry, EpisodeScore | None]


def record_path(results_dir: Path, scenario_id: str) -> Path:
    return Path(results_dir) / RECORDS_DIR / f"{scenario_id}{RECORD_SUFFIX}"


def score_outcomes(
    outcomes: Iterable[ScenarioOutcome],
    suite: Suite,
    profile: ScoringProfile,
    *,
    submission: str,
    running: Iterable[str] = (),
    cache: dict[str, ScoredEntry] | None = None,
) -> Summary:
    """The summary of ``suite``'s scenarios: scored from their outcomes' records, ``running``
    for the ids given, ``pending`` for the rest. ``cache`` (scenario id -> scored entry) saves
    re-reading records when a summary is rewritten after every scenario."""
    by_id = {outcome.scenario_id: outcome for outcome in outcomes}
    running = set(running)
    cache = {} if cache is None else cache
    entries, scores = [], []
    for scenario in suite.scenarios:
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
        suite=suite.name,
        manifest_hash=suite.sha256,
        profile=ProfileRef(**profile.ref),
        complete=all(e.status in FINISHED for e in entries),
        metrics=aggregate(scores),
        families=by_family(scores, suite.family_of()),
        uncharged=tuple(e.id for e in entries if e.status in UNCHARGED),
        scenarios=tuple(entries),
    )


def score_outcome(
    scenario: ManifestEntry, outcome: ScenarioOutcome, profile: ScoringProfile
) -> ScoredEntry:
    """The summary entry of a finished scenario and, when charged, its score.

    The one charging rule: only ``done`` scenarios are charged; a record that does not follow
    docs/records.md is ours, so its scenario becomes ``evaluator_error`` (uncharged)."""
    if outcome.status == ScenarioStatus.done:
        try:
            return _score_done(scenario, outcome, profile)
        except RecordError as exc:
            outcome = replace(
                outcome,
                status=ScenarioStatus.evaluator_error,
                record_path=None,
                error=f"unusable episode record: {exc}",
            )
    entry = ScenarioEntry(
        id=scenario.id,
        family=scenario.family,
        status=outcome.status,
        steps=outcome.steps,
        error=outcome.error,
    )
    return entry, None


def _score_done(
    scenario: ManifestEntry, outcome: ScenarioOutcome, profile: ScoringProfile
) -> ScoredEntry:
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
        agents=agents,
        metrics=scenario_metrics(score),
        terms={name: total / max(score.weight, 1) for name, total in score.term_sums.items()},
    )
    return entry, score


def score_results_dir(results_dir: Path, profile: ScoringProfile) -> Summary:
    """Re-score a results folder from its records and ``summary.json``, without simulating."""
    stored = read_summary(results_dir)
    suite = Suite(
        root=Path(results_dir),
        manifest=SuiteManifest(
            suite=stored.suite,
            scenarios=tuple(ManifestEntry(id=e.id, family=e.family) for e in stored.scenarios),
        ),
        sha256=stored.manifest_hash,
    )
    outcomes = [
        stored_outcome(entry, results_dir) for entry in stored.scenarios if entry.status in FINISHED
    ]
    running = [entry.id for entry in stored.scenarios if entry.status == ScenarioStatus.running]
    return score_outcomes(outcomes, suite, profile, submission=stored.submission, running=running)


def stored_outcome(entry: ScenarioEntry, results_dir: Path) -> ScenarioOutcome:
    path = record_path(results_dir, entry.id)
    return ScenarioOutcome(
        scenario_id=entry.id,
        status=entry.status,
        steps=entry.steps,
        agents=entry.agents,
        record_path=path if path.exists() else None,
        error=entry.error,
    )


def is_finished(entry: ScenarioEntry, results_dir: Path) -> bool:
    """Done with its record present (or no agent drove a step, so none was written)."""
    if entry.status != ScenarioStatus.done:
        return False
    drove = any(agent.steps for agent in entry.agents)
    return record_path(results_dir, entry.id).exists() or not drove
