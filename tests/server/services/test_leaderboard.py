"""Leaderboard ranking (the scoring spec's order, through evaluator.scoring.rank), best submission
per team, the cache and its invalidation, CSV."""

from __future__ import annotations

import csv
import io
from datetime import timedelta

import numpy as np

from evaluator.scoring import MetricSamples, bootstrap_interval
from server.core.queue import TaskQueue
from server.models import utcnow
from server.services import submissions
from server.services.leaderboard import LeaderboardCache
from server.status import SubmissionStatus
from server.tracks import Track
from tests.evaluator.scoring.builders import simulated
from tests.server.builders import bearer, make_team, seed_scored


def board(client, track="freestyle"):
    response = client.get("/api/v1/leaderboard", params={"track": track})
    assert response.status_code == 200
    return response.json()["entries"]


def test_lexicographic_order_best_per_team_ties_to_the_earlier(client, db):
    t0 = utcnow() - timedelta(hours=5)
    teams = {name: make_team(db, name)[0] for name in ("a", "b", "c", "d", "e")}
    # completion decides first, even against a far better time.
    seed_scored(db, teams["a"], (0.5, 100.0, 0.1, 0.0), created_at=t0)
    seed_scored(db, teams["b"], (0.25, 700.0, 0.9, 0.9), created_at=t0)
    # Same completion: time breaks the tie; then humanness.
    seed_scored(db, teams["c"], (0.25, 600.0, 0.9, 0.9), created_at=t0)
    seed_scored(db, teams["d"], (0.25, 600.0, 0.8, 0.9), created_at=t0 + timedelta(hours=1))
    # A full tie with d goes to the earlier submission (d).
    seed_scored(db, teams["e"], (0.25, 600.0, 0.8, 0.9), created_at=t0 + timedelta(hours=2))
    # Team a's better second submission replaces its first; its worse third does not.
    best_a = seed_scored(db, teams["a"], (0.0, 300.0, 0.5, 0.5), created_at=t0 + timedelta(hours=3))
    seed_scored(db, teams["a"], (0.75, 300.0, 0.5, 0.5), created_at=t0 + timedelta(hours=4))
    # Unscored and disqualified submissions are never ranked; another track is separate.
    seed_scored(db, teams["b"], (0.0, 1.0, 0.0, 0.0), status=SubmissionStatus.disqualified)
    seed_scored(db, teams["c"], (0.0, 1.0, 0.0, 0.0), status=SubmissionStatus.running)
    seed_scored(db, teams["e"], (0.0, 1.0, 0.0, 0.0), track=Track.offline)
    entries = board(client)
    assert [e["team"] for e in entries] == ["a", "d", "e", "c", "b"]
    assert [e["rank"] for e in entries] == [1, 2, 3, 4, 5]
    assert entries[0]["submission_id"] == best_a
    assert [e["team"] for e in board(client, "offline")] == ["e"]


def test_leaderboard_shows_per_family_metrics(client, db):
    team, _ = make_team(db, "a")
    families = {
        "merge": {"completion": 0.5, "time": 500.0, "humanness": 0.2, "rules": 0.0, "scenarios": 2}
    }
    seed_scored(db, team, (0.5, 500.0, 0.2, 0.0), families=families)
    assert board(client)[0]["families"] == families


def test_cache_serves_until_a_score_changes_the_generation(settings, db):
    team, _ = make_team(db, "a")
    cache = LeaderboardCache(db, recheck_s=3600)
    assert cache.get(Track.freestyle).board.entries == []
    seed_scored(db, team, (0.5, 500.0, 0.2, 0.0))
    # Within the re-check interval the cached board is served as it was...
    assert cache.get(Track.freestyle).board.entries == []
    # ...and once the generation is looked at again, the new score shows.
    cache.recheck_s = 0
    assert [e.team for e in cache.get(Track.freestyle).board.entries] == ["a"]


def test_disqualification_drops_the_entry(client, db, settings):
    team, _ = make_team(db, "a")
    sid = seed_scored(db, team, (0.5, 500.0, 0.2, 0.0))
    client.app.state.leaderboard.recheck_s = 0
    assert len(board(client)) == 1
    submissions.disqualify(db, TaskQueue(settings), sid, "copied")
    assert board(client) == []


def test_csv_export(client, db):
    team, _ = make_team(db, "a b")
    seed_scored(db, team, (0.25, 412.5, 0.125, 0.0), method_name='lanes, "best"')
    response = client.get("/api/v1/leaderboard.csv")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(response.text)))
    assert rows[0]["team"] == "a b"
    assert rows[0]["method_name"] == 'lanes, "best"'
    assert float(rows[0]["time"]) == 412.5


def test_an_entry_that_never_drove_shows_dashes_and_ranks_last(client, db):
    never = make_team(db, "never")[0]
    drove = make_team(db, "drove")[0]
    t0 = utcnow() - timedelta(hours=1)
    seed_scored(db, never, (1.0, 800.0, None, None), created_at=t0)
    seed_scored(db, drove, (1.0, 800.0, 40.0, 2.5), created_at=t0 + timedelta(minutes=5))
    entries = board(client)
    assert [e["team"] for e in entries] == ["drove", "never"]
    assert entries[1]["metrics"]["humanness"] is None and entries[1]["metrics"]["rules"] is None
    page = client.get("/").text
    row = page[page.index(">never<") :].split("</tr>")[0]
    assert row.count("—") == 2 and "0.0000" not in row
    rows = list(csv.DictReader(io.StringIO(client.get("/api/v1/leaderboard.csv").text)))
    assert (rows[1]["team"], rows[1]["humanness"], rows[1]["rules"]) == ("never", "", "")


def paired_entries(db, rng) -> None:
    """The final phase the issue met: two teams evaluated on one suite, B failing a little more
    than A scenario by scenario; their completion intervals overlap, yet paired over the suite
    the difference is certain."""
    a = simulated(rng, rng.random(60), scenarios=60, episodes=1)
    b_table = {sid: rows.copy() for sid, rows in a.scenarios.items()}
    for sid in list(b_table)[::6]:
        b_table[sid][:, 0] = 1.0
    b = MetricSamples("suite", b_table)
    t0 = utcnow() - timedelta(hours=1)
    for name, samples in (("a", a), ("b", b)):
        per_scenario = [rows[:, 0].tolist() for rows in samples.scenarios.values()]
        interval = bootstrap_interval(per_scenario)
        seed_scored(
            db,
            make_team(db, name)[0],
            tuple(samples.metrics()),
            samples=samples,
            interval=(interval.low, interval.high),
            created_at=t0,
        )


def test_tied_means_what_the_rank_ranges_say_in_every_view(client, db, arena):
    """Both entries were once badged "tied" and the team page said "statistically tied with
    rank 2" beside ranges "1" and "2" and beats_next 1.0: one definition now, everywhere."""
    paired_entries(db, np.random.default_rng(7))
    entries = board(client)
    first, second = (entries[0]["completion_interval"], entries[1]["completion_interval"])
    assert first["high"] >= second["low"]  # the intervals overlap
    assert [e["rank_range"] for e in entries] == ["1", "2"]
    assert entries[0]["beats_next"] > 0.975
    assert [e["tied_with"] for e in entries] == [[], []]

    page = client.get("/").text
    assert 'class="tied"' not in page.split('id="interval-legend"')[0]
    assert "rank 1 is certain" in page
    assert f"{100 * entries[0]['beats_next']:.1f}%" in page  # visible, not only on hover
    rows = list(csv.DictReader(io.StringIO(client.get("/api/v1/leaderboard.csv").text)))
    assert [(row["rank_range"], row["tied_with"]) for row in rows] == [("1", ""), ("2", "")]

    shown = arena("submissions", "show", str(entries[0]["submission_id"]))
    assert "rank 1 is certain (no entry statistically tied)" in shown
    assert "tied with rank" not in shown


def test_a_range_is_tied_in_every_view_and_the_standing_carries_it(client, db):
    rng = np.random.default_rng(11)
    a, b = simulated(rng, 0.2, scenarios=60), simulated(rng, 0.2, scenarios=60)
    t0 = utcnow() - timedelta(hours=1)
    tokens = {}
    for name, samples in (("a", a), ("b", b)):
        team, tokens[name] = make_team(db, name)
        seed_scored(db, team, tuple(samples.metrics()), samples=samples, created_at=t0)
    entries = board(client)
    assert [e["rank_range"] for e in entries] == ["1-2", "1-2"]
    assert [e["tied_with"] for e in entries] == [[2], [1]]
    second = entries[1]
    detail = client.get(
        f"/api/v1/submissions/{second['submission_id']}", headers=bearer(tokens[second["team"]])
    ).json()
    standing = detail["standing"]
    assert (standing["rank"], standing["rank_range"], standing["tied_with"]) == (2, "1-2", [1])
    assert (standing["rank_low"], standing["rank_high"]) == (1, 2)
    assert standing["statistics"] == "could rank 1 to 2 (statistically tied with rank 1)"
    page = client.get("/").text.split('id="interval-legend"')[0]
    assert page.count('class="tied"') == 2
    assert page.count('class="rank-chart"') == 2


def test_one_rounding_everywhere(client, db, arena):
    """An interval once read 0.5313 on the submission page and 0.5312 on the leaderboard and
    in the CLI: a half at the fourth decimal is rounded alike by every view."""
    team, _ = make_team(db, "alpha")
    sid = seed_scored(db, team, (0.53125, 412.25, 0.1, 0.0), interval=(0.40625, 0.65625))
    page = client.get("/").text
    assert "0.5313" in page and "[0.4063, 0.6563]" in page and "412.3" in page
    shown = arena("submissions", "show", str(sid))
    assert "completion 0.5313 [0.4063, 0.6563], time 412.3" in shown
    assert "0.5313" in arena("submissions", "list")


def test_rank_ranges_share_ranks_the_bootstrap_cannot_tell_apart(client, db):
    """Stored per-episode values decide the rank ranges: two equal agents share ranks 1-2,
    a clearly worse one holds rank 3 alone; the chance to beat the neighbour is in the JSON,
    the CSV and the page's hover text."""
    rng = np.random.default_rng(11)
    a, b = simulated(rng, 0.2, scenarios=60), simulated(rng, 0.2, scenarios=60)
    worse = simulated(rng, 0.8, scenarios=60)
    t0 = utcnow() - timedelta(hours=1)
    for name, samples in (("a", a), ("b", b), ("worse", worse)):
        seed_scored(
            db, make_team(db, name)[0], tuple(samples.metrics()), samples=samples, created_at=t0
        )
    # One scored before per-episode values were kept: it keeps its own rank, unrangeable.
    seed_scored(db, make_team(db, "old")[0], (0.95, 800.0, 0.5, 0.1), created_at=t0)
    entries = board(client)
    assert [e["team"] for e in entries][2:] == ["worse", "old"]
    assert [e["rank_range"] for e in entries] == ["1-2", "1-2", "3", "4"]
    assert [(e["rank_low"], e["rank_high"]) for e in entries] == [(1, 2), (1, 2), (3, 3), (4, 4)]
    chances = [e["beats_next"] for e in entries]
    assert 0.5 <= chances[0] < 0.975 and chances[1] > 0.975 and chances[2:] == [None, None]
    assert [e["compared"] for e in entries] == [True, True, True, False]

    rows = list(csv.DictReader(io.StringIO(client.get("/api/v1/leaderboard.csv").text)))
    assert [row["rank_range"] for row in rows] == ["1-2", "1-2", "3", "4"]
    assert float(rows[0]["beats_next"]) == chances[0] and rows[3]["beats_next"] == ""

    page = client.get("/").text
    assert page.count('class="rank-range"') == 4 + 1  # and the legend
    assert f"ahead of rank 2 in {100 * chances[0]:.1f}% of" in page


def test_a_rescore_or_a_new_best_changes_the_ranges_and_the_cache_keeps_only_the_board(
    settings, db
):
    rng = np.random.default_rng(12)
    cache = LeaderboardCache(db, recheck_s=0)
    a, b = simulated(rng, 0.2, scenarios=60), simulated(rng, 0.25, scenarios=60)
    team_a, team_b = make_team(db, "a")[0], make_team(db, "b")[0]
    first = seed_scored(db, team_a, tuple(a.metrics()), samples=a)
    seed_scored(db, team_b, tuple(b.metrics()), samples=b)
    assert [e.rank_range for e in cache.get(Track.freestyle).board.entries] == ["1-2", "1-2"]
    # Team b's far better second submission replaces its first on the board.
    better = simulated(rng, 0.0, scenarios=60)
    seed_scored(db, team_b, tuple(better.metrics()), samples=better)
    entries = cache.get(Track.freestyle).board.entries
    assert [(e.team, e.rank_range) for e in entries] == [("b", "1"), ("a", "2")]
    assert entries[1].submission_id == first
    assert len(cache._replicates[("final", Track.freestyle)]) == 2


def test_a_scored_run_keeps_the_values_its_metrics_are_built_from(db, settings):
    """Through the real scoring path: the stored samples rebuild the stored metrics."""
    from sqlalchemy import select

    from evaluator.scoring import MetricSamples
    from server.models import Score
    from tests.server.builders import queued_submission
    from tests.server.worker.test_evaluation_flow import run_everything, start

    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid), success=False)
    with db.read_session() as session:
        score = session.scalar(select(Score))
        samples = MetricSamples.from_json(score.samples)
        stored = (score.completion, score.time, score.humanness, score.rules)
    assert len(samples.scenarios) == 3
    assert np.allclose(samples.metrics(), np.array(stored, dtype=float), equal_nan=True)


def test_while_a_board_is_recomputed_the_previous_one_is_served(settings, db):
    team, _ = make_team(db, "a")
    cache = LeaderboardCache(db, recheck_s=0)
    assert cache.get(Track.freestyle).board.entries == []
    seed_scored(db, team, (0.5, 500.0, 0.2, 0.0))
    with cache._lock(("final", Track.freestyle)):  # another request is computing it
        assert cache.get(Track.freestyle).board.entries == []
    assert [e.team for e in cache.get(Track.freestyle).board.entries] == ["a"]


def test_computing_one_board_holds_up_no_other(settings, db):
    """The start-up warm-up computing another phase's board must not make a request for this
    one take its older board."""
    team, _ = make_team(db, "a")
    cache = LeaderboardCache(db, recheck_s=0)
    assert cache.get(Track.freestyle).board.entries == []
    seed_scored(db, team, (0.5, 500.0, 0.2, 0.0))
    with cache._lock(("validation", Track.freestyle)), cache._lock(("final", Track.offline)):
        assert [e.team for e in cache.get(Track.freestyle).board.entries] == ["a"]


def test_the_generalisation_gap_to_another_phase(client, db):
    """Teams with entries in both phases get final minus validation; others none; JSON, CSV,
    page."""
    a, b = make_team(db, "a")[0], make_team(db, "b")[0]
    seed_scored(db, a, (0.25, 400.0, 0.5, 0.1), phase="final")
    seed_scored(db, a, (0.0, 300.0, 0.25, None), phase="validation")
    seed_scored(db, b, (0.5, 500.0, 0.5, 0.1), phase="final")
    response = client.get(
        "/api/v1/leaderboard", params={"phase": "final", "gap_from": "validation"}
    )
    body = response.json()
    assert body["gap_from"] == "validation"
    first, second = body["entries"]
    assert first["gap"]["difference"] == {
        "completion": 0.25,
        "time": 100.0,
        "humanness": 0.25,
        "rules": None,  # not measured in validation
    }
    assert first["gap"]["metrics"]["completion"] == 0.0 and second["gap"] is None
    assert "gap" not in board(client)[0] or board(client)[0]["gap"] is None

    rows = list(
        csv.DictReader(
            io.StringIO(
                client.get(
                    "/api/v1/leaderboard.csv", params={"phase": "final", "gap_from": "validation"}
                ).text
            )
        )
    )
    assert (rows[0]["gap_completion"], rows[0]["gap_rules"], rows[1]["gap_time"]) == (
        "0.25",
        "",
        "",
    )
    assert "gap_completion" not in client.get("/api/v1/leaderboard.csv").text

    page = client.get("/", params={"phase": "final", "gap_from": "validation"}).text
    assert "gap vs validation" in page and "+0.2500" in page
    assert "gap vs" not in client.get("/", params={"phase": "final"}).text.split("<table")[1]
    unknown = client.get("/api/v1/leaderboard", params={"phase": "final", "gap_from": "nope"})
    assert unknown.status_code == 404


def test_warm_resamples_every_board_and_still_shows_a_later_score(db):
    a, _ = make_team(db, "a")
    b, _ = make_team(db, "b")
    seed_scored(db, a, (0.5, 500.0, 0.2, 0.0), samples=simulated(np.random.default_rng(1), 0.5))
    cache = LeaderboardCache(db, recheck_s=3600)
    cache.warm()
    resampled = {key for key, known in cache._replicates.items() if known}
    assert resampled == {("final", Track.freestyle)}
    # The warmed board is not trusted blindly: a score written after the warm-up shows.
    seed_scored(db, b, (0.25, 500.0, 0.2, 0.0))
    assert [e.team for e in cache.get(Track.freestyle).board.entries] == ["b", "a"]
