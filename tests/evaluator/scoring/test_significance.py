"""Rank ranges and the chance to beat a neighbour, tested on simulated agents of known
difference: equal agents share ranks most of the time, clearly different ones don't, and every
metric of the hierarchy can decide."""

import numpy as np
import pytest

from evaluator.scoring import MetricSamples, RankRange, rank_ranges
from evaluator.scoring.significance import beat_matrix, paired_difference, replicates
from tests.evaluator.scoring.builders import MAX_STEPS, simulated


def ordered(entries: list[MetricSamples]) -> list[MetricSamples]:
    """Leaderboard order by the hierarchy on the point metrics."""
    return sorted(entries, key=lambda e: tuple(np.nan_to_num(e.metrics(), nan=np.inf)))


def test_samples_give_back_the_metrics_they_were_built_from():
    table = {
        "a": np.array([[0.0, 300.0, 20.0, 2.0, 100.0], [1.0, 800.0, 60.0, 0.0, 300.0]]),
        "b": np.array([[0.5, 800.0, 10.0, 1.0, 50.0]]),
    }
    completion, time, humanness, rules = MetricSamples("x", table).metrics()
    assert completion == pytest.approx((0.5 + 0.5) / 2)
    assert time == pytest.approx((550.0 + 800.0) / 2)
    # Ratio of sums, each scenario's sums and weights the mean over its episodes.
    assert humanness == pytest.approx((40.0 + 10.0) / (200.0 + 50.0))
    assert rules == pytest.approx((1.0 + 1.0) / (200.0 + 50.0))
    again = MetricSamples.from_json(MetricSamples("x", table).to_json())
    assert np.array_equal(again.metrics(), MetricSamples("x", table).metrics())


def test_same_entries_same_ranges_and_the_seed_is_what_varies_them():
    rng = np.random.default_rng(1)
    entries = ordered([simulated(rng, 0.3) for _ in range(4)])
    assert rank_ranges(entries) == rank_ranges(entries)
    chances = [r.beats_next for r in rank_ranges(entries, seed=2)[:-1]]
    assert chances != [r.beats_next for r in rank_ranges(entries, seed=3)[:-1]]


def test_equal_agents_share_ranks_most_of_the_time():
    rng = np.random.default_rng(2)
    shared = 0
    trials = 60
    for _ in range(trials):
        a, b = ordered([simulated(rng, 0.3), simulated(rng, 0.3)])
        first, second = rank_ranges([a, b], resamples=500)
        shared += first.high == 2 and second.low == 1
        assert 0.0 <= first.beats_next <= 1.0
    # A two-sided test at 95%: about 5% of equal pairs are separated by chance.
    assert shared / trials >= 0.85


def test_clearly_different_agents_do_not_share_ranks():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = ordered([simulated(rng, 0.1), simulated(rng, 0.6)])
        first, second = rank_ranges([a, b], resamples=500)
        assert (first.label, second.label) == ("1", "2")
        assert first.beats_next > 0.975


def test_a_range_spans_the_agents_it_cannot_be_told_from():
    rng = np.random.default_rng(4)
    entries = ordered(
        [simulated(rng, 0.05, scenarios=80)]
        + [simulated(rng, 0.4, scenarios=80) for _ in range(3)]
        + [simulated(rng, 0.9, scenarios=80)]
    )
    ranges = rank_ranges(entries)
    assert ranges[0].label == "1"
    assert ranges[-1].label == "5"
    for middle in ranges[1:4]:
        assert middle.low >= 2 and middle.high <= 4 and middle.low < middle.high
    for position, r in enumerate(ranges, start=1):
        assert r.low <= position <= r.high


def test_time_decides_when_completion_is_equal_and_so_does_humanness():
    rng = np.random.default_rng(5)
    fast, slow = simulated(rng, 0.0, time=250.0), simulated(rng, 0.0, time=400.0)
    assert rank_ranges([fast, slow])[0].label == "1"
    assert rank_ranges([fast, slow])[0].beats_next == 1.0
    # Every mission failed: completion and time are equal in every resample, humanness decides.
    smooth, jerky = simulated(rng, 1.0, humanness=0.2), simulated(rng, 1.0, humanness=0.9)
    first, second = rank_ranges([smooth, jerky])
    assert (first.label, second.label) == ("1", "2")
    twin = MetricSamples(smooth.suite, dict(smooth.scenarios))
    assert rank_ranges([smooth, twin])[0] == RankRange(1, 1, 2, beats_next=0.5)


def test_an_agent_that_drove_beats_one_that_never_did_in_every_resample():
    rng = np.random.default_rng(6)
    drove, never = simulated(rng, 1.0), simulated(rng, 1.0, drove=False)
    assert np.isnan(never.metrics()[2])
    assert rank_ranges([drove, never])[0].beats_next == 1.0


def test_pairing_over_a_shared_suite_sees_a_consistent_small_difference():
    # Scenarios of very different difficulty; b fails a little more often than a in each.
    rng = np.random.default_rng(7)
    difficulty = rng.random(60)
    a = simulated(rng, difficulty, scenarios=60, episodes=1)
    b_table = {sid: rows.copy() for sid, rows in a.scenarios.items()}
    for sid in list(b_table)[::6]:
        b_table[sid][:, 0] = 1.0
        b_table[sid][:, 1] = MAX_STEPS
    paired = MetricSamples("suite", b_table)
    unpaired = MetricSamples("another suite", b_table)
    assert paired.metrics()[0] > a.metrics()[0]
    together = rank_ranges([a, paired])
    apart = rank_ranges([a, unpaired])
    assert together[0].label == "1" and together[0].beats_next > 0.975
    assert apart[0].high == 2  # drawn independently, the suite's spread hides the difference


def test_tied_means_sharing_a_rank_range_and_nothing_else():
    """Two entries paired over one suite whose completion intervals overlap but whose ranks are
    certain are not tied (the badge once said they were, beside ranges "1" and "2")."""
    rng = np.random.default_rng(7)
    a = simulated(rng, rng.random(60), scenarios=60, episodes=1)
    b_table = {sid: rows.copy() for sid, rows in a.scenarios.items()}
    for sid in list(b_table)[::6]:
        b_table[sid][:, 0] = 1.0
    first, second = rank_ranges([a, MetricSamples("suite", b_table)])
    assert (first.label, second.label) == ("1", "2") and first.beats_next > 0.975
    assert first.tied_with == second.tied_with == ()
    assert first.statement.startswith("rank 1 is certain (no entry statistically tied); ahead")
    spread = RankRange(rank=2, low=1, high=4, beats_next=0.53125)
    assert spread.tied_with == (1, 3, 4)
    assert spread.statement == (
        "could rank 1 to 4 (statistically tied with ranks 1 and 3 and 4); ahead of rank 3 in "
        "53.1% of the bootstrap resamples"
    )
    assert (
        RankRange(3, 2, 3, None).statement == "could rank 2 to 3 (statistically tied with rank 2)"
    )


def test_a_paired_difference_sees_what_the_two_intervals_side_by_side_do_not():
    rng = np.random.default_rng(7)
    a = simulated(rng, rng.random(60), scenarios=60, episodes=2)
    b_table = {sid: rows.copy() for sid, rows in a.scenarios.items()}
    for sid in list(b_table)[::6]:
        b_table[sid][:, 0] = 1.0
    b_table["only in b"] = b_table[next(iter(b_table))]
    b = MetricSamples("suite", b_table)
    pair = paired_difference(a, b)
    assert pair.scenarios == 60  # the scenario only B ran is left out
    shared = MetricSamples("suite", {sid: b_table[sid] for sid in a.scenarios})
    assert pair.difference[0] == pytest.approx(shared.metrics()[0] - a.metrics()[0])
    assert 0 < pair.low[0] <= pair.difference[0] <= pair.high[0]
    assert pair.b_ahead < 0.025
    # Against itself: no difference at all, in every resample.
    same = paired_difference(a, a)
    assert same.difference[:2] == same.low[:2] == same.high[:2] == (0.0, 0.0)
    assert same.b_ahead == 0.5
    assert paired_difference(a, MetricSamples("another suite", b_table)) is None


def test_entries_without_samples_keep_their_rank_and_no_range_crosses_them():
    rng = np.random.default_rng(8)
    a, b = ordered([simulated(rng, 0.3), simulated(rng, 0.3)])
    ranges = rank_ranges([a, None, b])
    assert [r.label for r in ranges] == ["1", "2", "3"]
    assert ranges[0].beats_next is None and ranges[1].beats_next is None
    assert [r.compared for r in ranges] == [True, False, True]
    assert ranges[1].statement.startswith("rank 2: scored before per-episode values were kept")


def test_paired_replicates_of_one_agent_are_identical():
    rng = np.random.default_rng(9)
    a = simulated(rng, 0.3)
    first = replicates(a, resamples=200)
    second = replicates(MetricSamples(a.suite, dict(reversed(a.scenarios.items()))), resamples=200)
    assert np.array_equal(first, second, equal_nan=True)
    assert beat_matrix([first, second])[0, 1] == 0.5
