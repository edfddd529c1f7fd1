"""What every admin command acts on and how it refuses (server/commands/context.py): no database,
ids out of range, bad input: a message, never a traceback. Run against a real database (both
backends), configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

import pytest

from arena.config import get_settings
from arena_command import app
from tests.cli_runner import CliRunner

runner = CliRunner()


def test_without_a_database_admin_says_what_to_do_and_creates_nothing(tmp_path, monkeypatch):
    """No ARENA_DATA_DIR: a message naming `arena up` and the settings, no ./.arena/arena.db, no
    traceback; a database file without the schema is named as not migrated."""
    for name in ("DATA_DIR", "DATABASE_URL", "BROKER_URL"):
        monkeypatch.delenv(f"ARENA_{name}", raising=False)
    monkeypatch.chdir(tmp_path)
    get_settings.cache_clear()
    try:
        for args in (("teams", "list"), ("status",), ("submissions", "list")):
            result = runner.invoke(app, ["admin", *args])
            assert result.exit_code == 1
            assert "no database at" in result.output and "arena up" in result.output
            assert "ARENA_DATA_DIR" in result.output and "ARENA_DATABASE_URL" in result.output
            assert "Traceback" not in result.output and len(result.output.splitlines()) <= 3
        assert not (tmp_path / ".arena").exists()
        (tmp_path / ".arena").mkdir()
        (tmp_path / ".arena" / "arena.db").write_bytes(b"")
        result = runner.invoke(app, ["admin", "teams", "list"])
        assert result.exit_code == 1 and "not migrated" in result.output
        assert "arena admin db upgrade" in result.output
    finally:
        get_settings.cache_clear()


@pytest.mark.parametrize(
    "args",
    [
        ("submissions", "show", str(2**63)),
        ("submissions", "show", str(2**31)),
        ("submissions", "cancel", str(2**64)),
        ("submissions", "disqualify", "0"),
        ("submissions", "requeue", str(2**63)),
        ("rerun", str(2**63)),
        ("rescore", str(2**63)),
        ("submissions", "list", "--limit", "-1"),
        ("leaderboard", "export", "--track", "bogus"),
        ("leaderboard", "export", "--out", "/proc/no/such/folder/board.csv"),
        ("leaderboard", "export", "--out", "/"),
    ],
)
def test_bad_input_gets_a_message_not_a_traceback(arena, args):
    output = arena(*args, ok=False)
    assert "Traceback" not in output
    assert any(word in output for word in ("error", "Invalid value", "not in the range")), output
