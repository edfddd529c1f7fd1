"""The bootstrap interval of completion and the tie marks between leaderboard neighbours."""

import numpy as np
import pytest

from evaluator.scoring import Interval, bootstrap_interval


def test_identical_values_give_a_point_interval():
    assert bootstrap_interval([[0.5, 0.5], [0.5], [0.5, 0.5]]) == Interval(0.5, 0.5)


def test_two_scenarios_known_example():
    # Scenarios failing 0 and 1: a resample's mean is 0, 0.5 or 1 with chances 1/4, 1/2, 1/4,
    # so the 2.5th and 97.5th percentiles are 0 and 1.
    assert bootstrap_interval([[0.0], [1.0]]) == Interval(0.0, 1.0)


def test_episodes_within_a_scenario_are_resampled_too():
    # One scenario: only its episodes can vary the mean.
    interval = bootstrap_interval([[0.0, 1.0, 0.0, 1.0]])
    assert interval.low < 0.5 < interval.high


def test_same_data_same_interval_and_the_seed_is_what_varies_it():
    data = [[0.0, 1.0], [1.0, 1.0], [0.0], [0.5, 0.0], [1.0]]
    assert bootstrap_interval(data) == bootstrap_interval(data)
    assert bootstrap_interval(data, seed=1) != bootstrap_interval(data, seed=2)


def test_interval_holds_the_mean_and_narrows_with_more_scenarios():
    rng = np.random.default_rng(0)
    small = [[float(v)] for v in rng.random(20) < 0.3]
    large = [[float(v)] for v in rng.random(500) < 0.3]
    a, b = bootstrap_interval(small), bootstrap_interval(large)
    assert a.low <= np.mean(small) <= a.high
    assert b.high - b.low < a.high - a.low


def test_coverage_is_near_the_level():
    """Over many simulated evaluations of an agent failing 30% of scenarios, the 95% interval
    holds the true rate about 95% of the time (the percentile bootstrap runs a little low)."""
    rng = np.random.default_rng(1)
    hits = 0
    trials = 200
    for trial in range(trials):
        values = [[float(v)] for v in rng.random(60) < 0.3]
        interval = bootstrap_interval(values, resamples=500, seed=trial)
        hits += interval.low <= 0.3 <= interval.high
    assert 0.88 <= hits / trials <= 0.99


def test_empty_input_is_refused():
    with pytest.raises(ValueError):
        bootstrap_interval([])
    with pytest.raises(ValueError):
        bootstrap_interval([[0.5], []])
