"""A submission's score over its training seeds: the crossed interval, the spread, the means."""

import numpy as np
import pytest

from evaluator.scoring import Interval, MetricSamples, bootstrap_interval
from evaluator.scoring.seeds import (
    Spread,
    completion_table,
    mean_families,
    mean_metrics,
    pooled_samples,
    seed_interval,
    spread,
)


def _samples(failures: dict[str, list[float]], suite: str = "suite") -> MetricSamples:
    """Samples whose episodes failed as given (time 10, no humanness or rules terms)."""
    return MetricSamples(
        suite=suite,
        scenarios={
            sid: np.array([[f, 10.0, 0.0, 0.0, 1.0] for f in values])
            for sid, values in failures.items()
        },
    )


def test_identical_values_give_a_point_interval():
    assert seed_interval([[0.25, 0.25], [0.25, 0.25], [0.25, 0.25]]) == Interval(0.25, 0.25)


def test_two_seeds_known_example():
    # Seeds failing every scenario and none: a resample's mean is 0, 0.5 or 1 with chances
    # 1/4, 1/2, 1/4, so the 2.5th and 97.5th percentiles are 0 and 1.
    assert seed_interval([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]) == Interval(0.0, 1.0)


def test_one_seed_resamples_the_scenarios_only():
    interval = seed_interval([[0.0, 1.0]])
    assert interval == Interval(0.0, 1.0)


def test_seeds_that_disagree_widen_the_interval():
    rng = np.random.default_rng(0)
    scenarios = rng.random(40) < 0.3
    same = np.array([scenarios, scenarios, scenarios], dtype=float)
    apart = same + np.array([[-0.2], [0.0], [0.2]])
    a, b = seed_interval(same), seed_interval(apart)
    assert a.low <= same.mean() <= a.high and b.low <= apart.mean() <= b.high
    assert b.high - b.low > a.high - a.low


def test_same_data_same_interval_and_the_seed_is_what_varies_it():
    data = np.random.default_rng(0).random((4, 12))
    assert seed_interval(data) == seed_interval(data)
    assert seed_interval(data, seed=1) != seed_interval(data, seed=2)


def test_coverage_on_simulated_seeds():
    """Simulated trainings: each seed shifts the completion error a little, each scenario a
    lot, and each (seed, scenario) pair has its own noise; the 95% interval over 8 seeds x 40
    scenarios holds the true mean about 95% of the time (crossed resampling errs wide)."""
    rng = np.random.default_rng(3)
    trials, hits = 200, 0
    for trial in range(trials):
        table = (
            0.3
            + rng.normal(0, 0.05, (8, 1))
            + rng.normal(0, 0.2, (1, 40))
            + rng.normal(0, 0.1, (8, 40))
        )
        interval = seed_interval(table, resamples=500, seed=trial)
        hits += interval.low <= 0.3 <= interval.high
    assert 0.9 <= hits / trials <= 1.0


def test_empty_input_is_refused():
    with pytest.raises(ValueError):
        seed_interval([])
    with pytest.raises(ValueError):
        seed_interval([[]])
    with pytest.raises(ValueError):
        spread([])


def test_spread_of_known_values():
    assert spread([0.1, 0.3, 0.2]) == Spread(low=0.1, high=0.3, std=pytest.approx(0.1))
    assert spread([0.4]) == Spread(low=0.4, high=0.4, std=0.0)


def test_completion_table_is_each_seed_per_scenario_mean():
    table = completion_table(
        [_samples({"b": [1.0], "a": [0.0, 1.0]}), _samples({"a": [1.0, 1.0], "b": [0.0]})]
    )
    np.testing.assert_array_equal(table, [[0.5, 1.0], [1.0, 0.0]])  # scenarios a, b


def test_seeds_on_other_scenarios_are_refused():
    with pytest.raises(ValueError):
        completion_table([_samples({"a": [0.0]}), _samples({"b": [0.0]})])
    with pytest.raises(ValueError):
        pooled_samples([_samples({"a": [0.0]}), _samples({"a": [0.0]}, suite="other")])


def test_pooled_samples_give_the_mean_over_seeds():
    seeds = [
        _samples({"a": [0.0, 1.0], "b": [1.0, 1.0]}),
        _samples({"a": [0.0, 0.0], "b": [0.0, 1.0]}),
    ]
    pooled = pooled_samples(seeds)
    assert pooled.scenarios["a"].shape == (4, 5)
    per_seed = [s.metrics()[0] for s in seeds]
    assert pooled.metrics()[0] == pytest.approx(np.mean(per_seed))
    # With one seed the interval over seeds x scenarios is the scenarios' interval of means.
    table = completion_table(seeds[:1])
    assert seed_interval(table) == bootstrap_interval([[v] for v in table[0]])


def test_mean_metrics_skip_what_a_seed_did_not_measure():
    means = mean_metrics(
        [
            {"completion": 0.2, "time": 10.0, "humanness": None, "rules": None},
            {"completion": 0.4, "time": 20.0, "humanness": 1.0, "rules": None},
        ]
    )
    assert means == {
        "completion": pytest.approx(0.3),
        "time": 15.0,
        "humanness": 1.0,
        "rules": None,
    }


def test_mean_families():
    one = {
        "merge": {"completion": 0.0, "time": 1.0, "humanness": 0.5, "rules": 0.1, "scenarios": 3}
    }
    two = {
        "merge": {"completion": 1.0, "time": 3.0, "humanness": 0.5, "rules": 0.3, "scenarios": 3}
    }
    assert mean_families([one, two]) == {
        "merge": {
            "completion": 0.5,
            "time": 2.0,
            "humanness": 0.5,
            "rules": pytest.approx(0.2),
            "scenarios": 3,
        }
    }
