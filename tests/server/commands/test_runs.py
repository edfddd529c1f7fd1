"""`arena admin rescore|rerun|retrain|compare|model` (server/commands/runs.py). Run against a real
database (both backends), configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

import csv
import io
import json

from tests.server.builders import make_team, queued_submission
from tests.server.worker.test_evaluation_flow import run_everything, start


def test_rescore_rerun_and_export(arena, db, settings):
    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid))
    output = arena("rescore", str(sid))
    assert "\t100.0\t" in output  # time of three successes at step 100, as every view writes it
    arena("rescore", "--all")
    refused = arena("rescore", "--phase", "final", "--profile", "nope", ok=False)
    assert "unknown scoring profile" in refused
    assert "attempt 2 queued" in arena("rerun", str(sid))
    # The old score stands meanwhile; the list says a re-run is going on, not just "scored".
    row = arena("submissions", "list").splitlines()[1].split("\t")
    # Its progress as its team sees it in a hidden phase: quarters (services/hidden_timing.py).
    assert (row[5], row[6]) == ("scored (re-run running)", "0/4 quarters")
    rows = list(csv.DictReader(io.StringIO(arena("leaderboard", "export"))))
    assert [(row["team"], float(row["completion"])) for row in rows] == [("alpha", 0.0)]
    # Alone on the board: its rank is certain and there is no neighbour to beat.
    assert (rows[0]["rank_range"], rows[0]["beats_next"]) == ("1", "")


def test_rescore_with_another_profile_is_for_a_whole_phase(arena, db, settings):
    team, _ = make_team(db, "alpha")
    first = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, first))
    second = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, second))
    refused = arena("rescore", str(first), "--profile", "driving-smarts-2022", ok=False)
    assert "give --phase NAME" in refused and "ranked unfairly" in refused
    assert "give --phase" in arena("rescore", "--all", "--profile", "driving-smarts-2022", ok=False)
    output = arena("rescore", "--phase", "final", "--profile", "driving-smarts-2022")
    assert "phase final is now scored with profile driving-smarts-2022" in output
    rows = [line.split("\t") for line in output.splitlines() if line[:1].isdigit()]
    # Submission ids, not run ids; every submission of the phase, by the same profile.
    assert [(row[0], row[2], row[3]) for row in rows] == [
        (str(first), "final", "driving-smarts-2022"),
        (str(second), "final", "driving-smarts-2022"),
    ]
    assert arena("rescore", str(second)).splitlines()[-1].startswith(f"{second}\t1\tfinal\t")


def test_compare_two_submissions_of_a_hidden_phase(arena, db, settings):
    team, _ = make_team(db, "alpha")
    worse = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, worse), success=False)
    better = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, better), success=True)
    output = arena("compare", str(worse), str(better))
    assert f"A: submission {worse} of alpha (final, attempt 1" in output
    lines = [line.split("\t") for line in output.splitlines()]
    # B - A, and B - A paired over the scenarios both ran: every one differs alike.
    assert next(row for row in lines if row[0] == "completion")[1:] == [
        "1.0000",
        "0.0000",
        "-1.0000",
        "[-1.0000, -1.0000] B better",
    ]
    ahead = next(row for row in lines if row[0] == "B ranks ahead of A")
    assert ahead[-1] == "100.0% of resamples over 3 shared scenarios"
    assert "3 episode(s) ended differently" in output
    document = json.loads(arena("compare", str(worse), str(better), "--json"))
    assert {row["b"] for row in document["differing_outcomes"]} == {"reached_goal"}
    paired = document["paired"]
    assert (paired["scenarios"], paired["b_ranks_ahead"]) == (3, 1.0)
    assert paired["completion"] == {"b_minus_a": -1.0, "low": -1.0, "high": -1.0}
    queued = queued_submission(db, team)
    assert "no score yet" in arena("compare", str(worse), str(queued), ok=False)
