"""`arena admin db ...` (server/commands/database.py). Run against a real database (both backends),
configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations


def test_db_upgrade_is_idempotent(arena):
    from server.core.migrate import head_revision

    assert f"revision {head_revision()}" in arena("db", "upgrade")
