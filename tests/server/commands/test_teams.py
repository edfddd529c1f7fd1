"""`arena admin teams ...` (server/commands/teams.py). Run against a real database (both backends),
configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

import re

from arena_command import app
from server.models import Submission
from tests.cli_runner import CliRunner
from tests.server.builders import make_team, queued_submission, seed_scored
from tests.server.worker.test_evaluation_flow import run_everything, start

runner = CliRunner()


def test_teams_create_list_rotate(arena, client):
    output = arena("teams", "create", "gamma")
    token = output.splitlines()[-1]  # alone on the last line
    assert re.fullmatch(r"arena_\S+", token)
    assert (
        client.get("/api/v1/submissions", headers={"Authorization": f"Bearer {token}"}).status_code
        == 200
    )
    assert "already exists" in arena("teams", "create", "gamma", ok=False)
    assert "no team named 'gama'; did you mean 'gamma'?" in arena(
        "teams", "rotate-token", "gama", ok=False
    )
    assert "gamma" in arena("teams", "list")
    new = re.search(r"(arena_\S+)", arena("teams", "rotate-token", "gamma")).group(1)
    assert (
        client.get("/api/v1/submissions", headers={"Authorization": f"Bearer {token}"}).status_code
        == 401
    )
    assert (
        client.get("/api/v1/submissions", headers={"Authorization": f"Bearer {new}"}).status_code
        == 200
    )


def test_delete_a_team_says_what_goes_and_asks(arena, db, settings):
    team, _ = make_team(db, "alpha")
    other, _ = make_team(db, "beta")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid))
    kept = seed_scored(db, other, (0.5, 400.0, 0.1, 0.0), phase="validation")
    result = runner.invoke(app, ["admin", "teams", "delete", "alpha"], input="n\n")
    assert result.exit_code == 1 and "nothing deleted" in result.output
    assert "team alpha: 1 submission(s) with their uploads, 1 evaluation(s)" in result.output
    assert "3 episode result(s)" in result.output and "1 API token(s)" in result.output
    assert "alpha" in arena("teams", "list")
    result = runner.invoke(app, ["admin", "teams", "delete", "alpha"], input="y\n")
    assert result.exit_code == 0 and "deleted team alpha" in result.output
    assert "alpha" not in arena("teams", "list")
    with db.session() as session:
        assert session.get(Submission, sid) is None
        assert session.get(Submission, kept) is not None
    assert "no team named 'alpha'" in arena("teams", "delete", "alpha", "--yes", ok=False)
