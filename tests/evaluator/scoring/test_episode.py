import numpy as np
import pytest

from arena.errors import RecordError
from arena.outcome import AgentOutcome
from evaluator.scoring import (
    aggregate,
    by_family,
    load_profile,
    load_record,
    score_episode,
    score_without_record,
)
from evaluator.scoring.registry import get_term
from tests.evaluator.scoring.builders import AgentSpec, drive, track, write_record

PROFILE = load_profile()


def scored(tmp_path, scenario_id: str, agents: list[AgentSpec], **kwargs):
    return score_episode(
        load_record(write_record(tmp_path / f"{scenario_id}.npz", scenario_id, agents, **kwargs)),
        PROFILE,
    )


def lively(n: int, over_limit: float = 0.0) -> dict[str, np.ndarray]:
    """Rows with non-zero humanness and rules terms: weaving in the lane, varying speed."""
    rng = np.random.default_rng(n)
    speed = 10.0 + rng.uniform(-1.0, 1.0, n)
    return drive(
        n,
        speed=speed,
        vx=speed,
        vy=0.0,
        lane_offset=rng.uniform(-1.0, 1.0, n),
        speed_limit=10.0 - over_limit,
    )


def expected_sums(rows: dict[str, np.ndarray]) -> tuple[float, float]:
    t = track(rows)
    humanness = sum(get_term(name)(t, PROFILE).sum() for name in PROFILE.humanness_terms)
    rules = sum(get_term(name)(t, PROFILE).sum() for name in PROFILE.rules_terms)
    return humanness, rules


def test_worked_example_of_the_spec(tmp_path):
    success_rows, crash_rows = lively(300), lively(120, over_limit=1.0)
    success = scored(tmp_path, "a", [AgentSpec(success_rows, done_step=300)])
    crash = scored(tmp_path, "b", [AgentSpec(crash_rows, reason="collision", done_step=120)])

    metrics = aggregate([success, crash])

    assert metrics.completion == 0.5
    assert metrics.time == (300 + 800) / 2
    h1, r1 = expected_sums(success_rows)
    h2, r2 = expected_sums(crash_rows)
    assert metrics.humanness == pytest.approx((h1 + h2) / 420)
    assert metrics.rules == pytest.approx((r1 + r2) / 420)
    assert metrics.humanness > 0 and metrics.rules > 0
    # a mean over agent-steps, not the mean of per-scenario means
    assert metrics.humanness != pytest.approx((h1 / 300 + h2 / 120) / 2)


def test_collided_agent_partial_steps_count(tmp_path):
    rows = lively(50, over_limit=2.0)
    score = scored(tmp_path, "c", [AgentSpec(rows, reason="collision", done_step=50)])
    assert score.agent_steps == 50
    assert (score.failure, score.time) == (1.0, 800)
    assert (score.humanness_sum, score.rules_sum) == pytest.approx(expected_sums(rows))


def test_multi_agent_scenario_with_one_failure_counts_half(tmp_path):
    score = scored(
        tmp_path,
        "m",
        [AgentSpec(drive(200), done_step=200), AgentSpec(drive(80), reason="off_road")],
    )
    assert score.failure == 0.5
    assert score.time == 800
    assert score.agent_steps == 280


def test_time_is_the_step_the_last_agent_reached_its_goal(tmp_path):
    score = scored(
        tmp_path, "m", [AgentSpec(drive(200), done_step=210), AgentSpec(drive(250), done_step=260)]
    )
    assert (score.failure, score.time) == (0.0, 260)


def test_failure_charges_the_profile_step_limit(tmp_path):
    rows = drive(800)
    score = scored(tmp_path, "t", [AgentSpec(rows, reason="max_episode_steps")])
    assert (score.failure, score.time) == (1.0, PROFILE.max_episode_steps)


def test_agent_that_never_drove_is_a_failure_with_no_steps():
    agents = [
        AgentOutcome(id="Agent_0", reached_goal=False, reason="init_timeout", steps=0, done_step=0)
    ]
    score = score_without_record("s", agents, PROFILE)
    assert (score.failure, score.time, score.agent_steps) == (1.0, 800, 0)
    # Nothing was measured: not 0 (the best value) but None, shown as "—".
    assert (aggregate([score]).humanness, aggregate([score]).rules) == (None, None)
    assert not aggregate([score]).drove


def test_a_set_with_one_driven_step_measures_humanness(tmp_path):
    never = score_without_record(
        "s",
        [
            AgentOutcome(
                id="Agent_0", reached_goal=False, reason="agent_error", steps=0, done_step=0
            )
        ],
        PROFILE,
    )
    drove = scored(tmp_path, "t", [AgentSpec(drive(50), reason="collision")])
    both = aggregate([never, drove])
    assert both.drove and both.humanness is not None and both.humanness >= 0


def test_record_with_another_step_length_is_refused(tmp_path):
    with pytest.raises(RecordError, match=r"expects 0\.1"):
        scored(tmp_path, "d", [AgentSpec(drive(3))], dt=0.05)


def test_record_missing_an_array_is_refused(tmp_path):
    path = write_record(tmp_path / "r.npz", "r", [AgentSpec(drive(3))])
    arrays = dict(np.load(path))
    del arrays["lane_width"]
    np.savez_compressed(path, **arrays)
    with pytest.raises(RecordError, match="lane_width"):
        load_record(path)


def test_families_aggregate_their_own_scenarios(tmp_path):
    a = scored(tmp_path, "a", [AgentSpec(drive(100), done_step=100)])
    b = scored(tmp_path, "b", [AgentSpec(drive(10), reason="collision")])
    c = scored(tmp_path, "c", [AgentSpec(drive(300), done_step=300)])
    families = by_family([a, b, c], {"a": "merge", "b": "merge", "c": "cruise"})
    assert list(families) == ["cruise", "merge"]
    assert (families["merge"].completion, families["merge"].time) == (0.5, 450.0)
    assert (families["cruise"].completion, families["cruise"].time) == (0.0, 300.0)


def test_empty_set_has_no_metrics():
    assert aggregate([]) is None
