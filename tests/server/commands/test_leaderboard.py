"""`arena admin leaderboard ...` (server/commands/leaderboard.py). Run against a real database (both
backends), configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

import csv
import io

from tests.server.builders import make_team, seed_scored


def test_leaderboard_export_names_the_tracks_and_the_unwritable_file(arena):
    refused = arena("leaderboard", "export", "--track", "bogus", ok=False)
    assert "'bogus' is not one of" in refused and "freestyle" in refused
    assert "Traceback" not in refused
    assert "no phase 'finale'" in arena("leaderboard", "export", "--phase", "finale", ok=False)
    unwritable = arena("leaderboard", "export", "--out", "/", ok=False)
    assert "cannot write /: Is a directory" in unwritable


def test_leaderboard_export_with_the_generalisation_gap(arena, db):
    team, _ = make_team(db, "a")
    seed_scored(db, team, (0.5, 400.0, 0.5, 0.1), phase="final")
    seed_scored(db, team, (0.25, 300.0, 0.5, 0.1), phase="validation")
    text = arena("leaderboard", "export", "--gap-from", "validation")
    rows = list(csv.DictReader(io.StringIO(text)))
    assert (rows[0]["team"], float(rows[0]["gap_completion"])) == ("a", 0.25)
    assert "no phase 'nope'" in arena("leaderboard", "export", "--gap-from", "nope", ok=False)
