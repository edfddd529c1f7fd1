"""Adaptive evaluation: episodes until completion's interval is tight.

A phase with an adaptive target runs its first round of episodes as any phase does. When a
round is finished, the run is scored as it stands; while completion's 95% interval is wider than
the target (its half-width above it) and the cap allows, every reactive scenario gets another
round of episodes. The episodes' seeds are those of any evaluation (arena/episodes.py: episode k
of a scenario always has the same traffic), and the decision depends only on the results, so a
submission that reruns bit-identically gets the same number of rounds.
"""

from __future__ import annotations

from pathlib import Path

from arena.episodes import episodes_of
from arena.suite import load_suite
from evaluator.scoring import load_profile
from server.core.artifacts import ArtifactStore
from server.core.queue import RunPlan
from server.models import EvaluationRun
from server.services import scoring
from server.services.evaluation import finished_count, lock
from server.status import ACTIVE_RUN


def half_width(run: EvaluationRun, store: ArtifactStore) -> float | None:
    """Half the width of completion's 95% interval over the run's finished episodes; None when
    nothing is charged yet or something is uncharged (the run then fails as any run does)."""
    summary = scoring.run_summary(run, load_profile(run.scoring_profile), store)
    interval = summary.completion_interval()
    if summary.uncharged or interval is None:
        return None
    return (interval.high - interval.low) / 2


def next_round(session, store: ArtifactStore, run_id: int) -> RunPlan | None:
    """Another round of episodes for a finished round of an adaptive run whose interval is still
    wider than its target (the episodes to send once committed); None when the run is to be
    scored now (not adaptive, tight enough, at the cap, or not finished)."""
    run = lock(session, EvaluationRun, run_id)
    if run.status not in ACTIVE_RUN or run.adaptive_target is None or run.max_episodes is None:
        return None
    if run.episodes_per_scenario >= run.max_episodes:
        return None
    if finished_count(session, run_id) < run.episode_count:
        return None
    width = half_width(run, store)
    if width is None or width <= run.adaptive_target:
        return None
    suite = load_suite(Path(run.suite_dir))
    before = run.episodes_per_scenario
    run.episodes_per_scenario = min(run.max_episodes, before + run.episode_round)
    episodes = episodes_of(suite.scenarios, run.episodes_per_scenario)
    run.episode_count = len(episodes)
    return RunPlan(run_id=run.id, episodes=tuple(e for e in episodes if e.index >= before))
