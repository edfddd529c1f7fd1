from evaluator.scoring import Metrics, rank


def metrics(completion=0.5, time=500.0, humanness=1.0, rules=0.1) -> Metrics:
    return Metrics(completion=completion, time=time, humanness=humanness, rules=rules)


def ranked(entries: list[tuple[str, Metrics | None, int]]) -> list[str]:
    order = rank(entries, metrics=lambda e: e[1], submitted_at=lambda e: e[2])
    return [name for name, _, _ in order]


def test_completion_decides_before_every_other_metric():
    entries = [
        ("fast_but_fails", metrics(completion=0.6, time=100, humanness=0, rules=0), 1),
        ("completes", metrics(completion=0.2, time=800, humanness=9, rules=9), 2),
    ]
    assert ranked(entries) == ["completes", "fast_but_fails"]


def test_each_metric_breaks_a_tie_on_the_previous_ones_only():
    entries = [
        ("rules", metrics(rules=0.3), 1),
        ("humanness", metrics(humanness=2.0, rules=0.0), 2),
        ("time", metrics(time=600.0, humanness=0.0, rules=0.0), 3),
        ("best", metrics(), 4),
    ]
    assert ranked(entries) == ["best", "rules", "humanness", "time"]


def test_full_tie_goes_to_the_earlier_submission():
    entries = [("later", metrics(), 5), ("earlier", metrics(), 3)]
    assert ranked(entries) == ["earlier", "later"]


def test_unscored_entries_come_after_every_scored_one():
    entries = [
        ("unscored_early", None, 1),
        ("worst", metrics(completion=1.0, time=800, humanness=50, rules=2), 9),
        ("unscored_late", None, 10),
    ]
    assert ranked(entries) == ["worst", "unscored_early", "unscored_late"]


def test_an_entry_that_never_drove_ranks_after_every_entry_that_drove():
    never = Metrics(completion=1.0, time=800.0, humanness=None, rules=None)
    entries = [
        ("never_drove_early", never, 1),
        (
            "drove_and_failed_everything",
            metrics(completion=1.0, time=800, humanness=50, rules=2),
            9,
        ),
        ("unscored", None, 0),
    ]
    assert ranked(entries) == ["drove_and_failed_everything", "never_drove_early", "unscored"]
