"""`arena admin db ...`: the database schema (`server/core/migrate.py`)."""

from __future__ import annotations

import typer

from server.commands.console import console

app = typer.Typer(no_args_is_help=True)


@app.command("upgrade")
def db_upgrade(revision: str = "head") -> None:
    """Apply the Alembic migrations to the configured database."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from server.core.migrate import current_revision, upgrade_database

    url = get_settings().storage.resolved_database_url
    upgrade_database(url, revision)
    console.print(f"database at revision [bold]{current_revision(url)}[/bold]")
