"""The evaluation core's scoring half: scenario outcomes -> :class:`Summary`.

``arena evaluate``, ``arena score`` and the service's workers all go through
:func:`score_outcomes`, so a local evaluation and the service can never disagree. Scores are
recomputed from the records every time, so re-scoring with a new profile needs no simulation.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

from arena.episodes import Episode, episode_count
from arena.errors import RecordError
from arena.outcome import FINISHED, UNCHARGED, AgentOutcome, ScenarioStatus
from arena.record_format import RECORD_SUFFIX
from arena.suite import ManifestEntry, Suite, SuiteManifest
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.scoring import (
    EpisodeScore,
    ScoringProfile,
    aggregate,
    by_family,
    load_record,
    mean_score,
    scenario_metrics,
    score_episode,
    score_without_record,
)
from evaluator.summary import EpisodeEntry, ProfileRef, ScenarioEntry, Summary, read_summary

RECORDS_DIR = "records"
LOGS_DIR = "logs"

# An episode's (or a scenario's) summary entry and, when charged, its score.
ScoredEntry = tuple[ScenarioEntry, EpisodeScore | None]


def record_path(results_dir: Path, name: str) -> Path:
    """The record of the episode named ``name`` (:attr:`arena.episodes.Episode.name`: the
    scenario id for a scenario's first episode)."""
    return Path(results_dir) / RECORDS_DIR / f"{name}{RECORD_SUFFIX}"


def score_outcomes(
    outcomes: Iterable[ScenarioOutcome],
    suite: Suite,
    profile: ScoringProfile,
    *,
    submission: str,
    episodes_per_scenario: int = 1,
    running: Iterable[Episode] = (),
    cache: dict[Episode, ScoredEntry] | None = None,
) -> Summary:
    """The summary of ``suite``'s scenarios, each reactive one run ``episodes_per_scenario``
    times: scored from their outcomes' records, ``running`` for the episodes given, ``pending``
    for the rest. A scenario's metrics are the mean over its episodes; it is charged once all
    of them are done. ``cache`` (episode -> scored entry) saves re-reading records when a
    summary is rewritten after every episode."""
    by_key = {outcome.key: outcome for outcome in outcomes}
    running = set(running)
    cache = {} if cache is None else cache
    entries, scores = [], []
    for scenario in suite.scenarios:
        states = []
        for index in range(episode_count(scenario, episodes_per_scenario)):
            key = Episode(scenario.id, index)
            outcome = by_key.get(key)
            if outcome is None:
                status = ScenarioStatus.running if key in running else ScenarioStatus.pending
                entry = ScenarioEntry(id=scenario.id, family=scenario.family, status=status)
                states.append((entry, None))
                continue
            if key not in cache:
                cache[key] = score_outcome(scenario, outcome, profile)
            states.append(cache[key])
        entry, score = states[0] if len(states) == 1 else _over_episodes(scenario, states)
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
        episodes_per_scenario=episodes_per_scenario,
    )


def _over_episodes(scenario: ManifestEntry, states: list[ScoredEntry]) -> ScoredEntry:
    """The entry of a scenario run several times, from its episodes' entries."""
    episodes = tuple(
        EpisodeEntry(
            index=index,
            status=entry.status,
            steps=entry.steps,
            agents=entry.agents,
            metrics=entry.metrics,
            error=entry.error,
        )
        for index, (entry, _) in enumerate(states)
    )
    common = {
        "id": scenario.id,
        "family": scenario.family,
        "steps": sum(e.steps for e in episodes),
        "episodes": episodes,
    }
    if not all(e.status in FINISHED for e in episodes):
        started = any(e.status != ScenarioStatus.pending for e in episodes)
        status = ScenarioStatus.running if started else ScenarioStatus.pending
        return ScenarioEntry(status=status, **common), None
    ours = next((e for e in episodes if e.status in UNCHARGED), None)
    if ours is not None:
        error = f"episode {ours.index}: {ours.error}"
        return ScenarioEntry(status=ours.status, error=error, **common), None
    score = mean_score([score for _, score in states])
    entry = ScenarioEntry(
        status=ScenarioStatus.done,
        metrics=scenario_metrics(score),
        terms=_term_means(score),
        **common,
    )
    return entry, score


def score_outcome(
    scenario: ManifestEntry, outcome: ScenarioOutcome, profile: ScoringProfile
) -> ScoredEntry:
    """The summary entry of a finished episode and, when charged, its score.

    The one charging rule: only ``done`` episodes are charged; a record that does not follow
    docs/records.md is ours, so its episode becomes ``evaluator_error`` (uncharged)."""
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
    return done_entry(scenario.id, scenario.family, steps, agents, score)


def done_entry(
    scenario_id: str,
    family: str,
    steps: int,
    agents: tuple[AgentOutcome, ...],
    score: EpisodeScore,
) -> ScoredEntry:
    """The summary entry of a ``done`` episode that scored ``score``."""
    entry = ScenarioEntry(
        id=scenario_id,
        family=family,
        status=ScenarioStatus.done,
        steps=steps,
        agents=agents,
        metrics=scenario_metrics(score),
        terms=_term_means(score),
    )
    return entry, score


def _term_means(score: EpisodeScore) -> dict[str, float]:
    return {
        name: total / score.weight if score.weight else 0.0
        for name, total in score.term_sums.items()
    }


def score_results_dir(results_dir: Path, profile: ScoringProfile) -> Summary:
    """Re-score a results folder from its records and ``summary.json``, without simulating."""
    stored = read_summary(results_dir)
    suite = Suite(
        root=Path(results_dir),
        manifest=SuiteManifest(
            suite=stored.suite,
            scenarios=tuple(
                ManifestEntry(id=e.id, family=e.family, reactive=e.episodes is not None)
                for e in stored.scenarios
            ),
        ),
        sha256=stored.manifest_hash,
    )
    episodes = [pair for entry in stored.scenarios for pair in stored_episodes(entry)]
    outcomes = [
        outcome_from_results_dir(key, episode, results_dir)
        for key, episode in episodes
        if episode.status in FINISHED
    ]
    running = [key for key, episode in episodes if episode.status == ScenarioStatus.running]
    summary = score_outcomes(
        outcomes,
        suite,
        profile,
        submission=stored.submission,
        episodes_per_scenario=stored.episodes_per_scenario,
        running=running,
    )
    if stored.manifest is None:
        return summary
    # The same runs, scored by this profile: only the manifest's profile changes.
    pinned = {"profile": profile.name, "profile_version": str(profile.version)}
    return summary.model_copy(update={"manifest": stored.manifest.model_copy(update=pinned)})


def stored_episodes(entry: ScenarioEntry) -> list[tuple[Episode, ScenarioEntry | EpisodeEntry]]:
    """A stored scenario's episodes: its own entry when it ran once."""
    if entry.episodes is None:
        return [(Episode(entry.id), entry)]
    return [(Episode(entry.id, e.index), e) for e in entry.episodes]


def outcome_from_results_dir(
    key: Episode, entry: ScenarioEntry | EpisodeEntry, results_dir: Path
) -> ScenarioOutcome:
    """The core's outcome back from a results folder's summary entry and record (a local
    evaluation resumed or re-scored; the service's counterpart is
    ``server.services.scoring.outcome_from_row``)."""
    path = record_path(results_dir, key.name)
    return ScenarioOutcome(
        scenario_id=key.scenario_id,
        episode=key.index,
        status=entry.status,
        steps=entry.steps,
        agents=entry.agents,
        record_path=path if path.exists() else None,
        error=entry.error,
    )


def is_finished(key: Episode, entry: ScenarioEntry | EpisodeEntry, results_dir: Path) -> bool:
    """Done with its record present (or no agent drove a step, so none was written)."""
    if entry.status != ScenarioStatus.done:
        return False
    drove = any(agent.steps for agent in entry.agents)
    return record_path(results_dir, key.name).exists() or not drove
