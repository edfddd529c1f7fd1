"""Adaptive evaluation through the service, as the worker's tasks drive it: rounds of episodes
until completion's interval is tight, up to the phase's cap; the same results give the same
rounds."""

from __future__ import annotations

import pytest
from sqlalchemy import select

from server.core.artifacts import DatabaseStore
from server.models import EvaluationRun, Score
from server.services import adaptive, evaluation, phases
from server.services.errors import InvalidInput
from tests.server.builders import make_team, queued_submission, report_episode


def evaluate(db, settings, submission_id, succeeds) -> list[int]:
    """Every episode of every round reported as workers do, ``succeeds(scenario, episode)``
    deciding each; the episodes per scenario after each aggregation."""
    with db.session() as session:
        plan = evaluation.start_evaluation(session, settings, submission_id)
    rounds = []
    while plan is not None:
        for episode in plan.episodes:
            succeeded = succeeds(episode.scenario_id, episode.index)
            report_episode(db, settings, plan, episode, reached_goal=succeeded)
        with db.session() as session:  # the aggregation task
            run_id = plan.run_id
            plan = adaptive.next_round(session, DatabaseStore(db), run_id)
            rounds.append(session.get(EvaluationRun, run_id).episodes_per_scenario)
            if plan is None:
                evaluation.finish_run(session, DatabaseStore(db), run_id)
    return rounds


def set_adaptive(db, settings, target=0.05, cap=6, first=2):
    phases.set_phase(
        db,
        settings,
        "final",
        phases.PhaseChanges(episodes_per_scenario=first, adaptive_target=target, max_episodes=cap),
    )


def test_a_wide_interval_gets_rounds_of_episodes_up_to_the_cap(db, settings):
    set_adaptive(db, settings)
    team, _ = make_team(db, "a")
    sid = queued_submission(db, team)
    # Every other episode fails: the interval stays wide, so rounds go on to the cap.
    assert evaluate(db, settings, sid, lambda s, k: k % 2 == 0) == [4, 6, 6]
    with db.read_session() as session:
        run = session.scalar(select(EvaluationRun))
        score = session.scalar(select(Score))
        assert (run.episode_count, run.status) == (3 * 6, "scored")
        assert score.completion == pytest.approx(0.5)
        assert score.manifest["episodes_per_scenario"] == 6


def test_a_tight_interval_stops_after_the_first_round(db, settings):
    set_adaptive(db, settings)
    team, _ = make_team(db, "a")
    sid = queued_submission(db, team)
    assert evaluate(db, settings, sid, lambda s, k: True) == [2]


def test_rounds_depend_only_on_the_results(db, settings):
    set_adaptive(db, settings, target=0.2, cap=10)
    team, _ = make_team(db, "a")

    # One scenario fails its first episodes only: the interval narrows as episodes come in.
    def results(s, k):
        return not (s.endswith("merge_0") and k < 3)

    first = evaluate(db, settings, queued_submission(db, team), results)
    again = evaluate(db, settings, queued_submission(db, team), results)
    assert first == again and 2 < first[-1] < 10


def test_the_phase_refuses_half_an_adaptive_setting(db, settings):
    with pytest.raises(InvalidInput, match="both"):
        phases.set_phase(db, settings, "final", phases.PhaseChanges(adaptive_target=0.05))
    with pytest.raises(InvalidInput, match="between 0 and 1"):
        phases.set_phase(
            db, settings, "final", phases.PhaseChanges(adaptive_target=2, max_episodes=5)
        )
    with pytest.raises(InvalidInput, match="at least the episodes of the first round"):
        set_adaptive(db, settings, cap=2, first=3)
