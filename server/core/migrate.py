"""Run the Alembic migrations programmatically (`arena admin db upgrade`, `arena up`, tests)."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy.engine import make_url
from sqlalchemy.exc import SQLAlchemyError

from arena.errors import ArenaError
from server.core.db import make_engine

REPO_ROOT = Path(__file__).resolve().parents[2]


def alembic_config(database_url: str) -> Config:
    config = Config(str(REPO_ROOT / "alembic.ini"))
    config.set_main_option("script_location", str(REPO_ROOT / "migrations"))
    # ConfigParser interpolation: a literal % in a password must be doubled.
    config.set_main_option("sqlalchemy.url", database_url.replace("%", "%%"))
    return config


def upgrade_database(database_url: str, revision: str = "head") -> None:
    command.upgrade(alembic_config(database_url), revision)


def current_revision(database_url: str) -> str | None:
    engine = make_engine(database_url)
    try:
        with engine.connect() as connection:
            return MigrationContext.configure(connection).get_current_revision()
    finally:
        engine.dispose()


def head_revision() -> str:
    """The newest migration: what an up-to-date database is at."""
    return ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head()


class DatabaseNotReady(ArenaError):
    """No database at the configured place, or one without the schema: a command that reads it
    says so instead of creating an empty file and failing on a missing table."""


_WHERE = (
    "run `arena up` (it creates and migrates the database under ARENA_DATA_DIR), or point this "
    "command at the service's database with ARENA_DATA_DIR or ARENA_DATABASE_URL"
)


def check_database_ready(database_url: str) -> None:
    """Raise :class:`DatabaseNotReady` unless ``database_url`` is a database at the newest
    migration. Never creates anything (a missing SQLite file stays missing)."""
    url = make_url(database_url)
    local_file = url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:")
    if local_file and not Path(url.database).exists():
        raise DatabaseNotReady(f"no database at {Path(url.database).resolve()}: {_WHERE}")
    try:
        revision = current_revision(database_url)
    except SQLAlchemyError as exc:
        reason = str(exc.orig if getattr(exc, "orig", None) else exc).strip().splitlines()[0]
        raise DatabaseNotReady(
            f"cannot open the database {url.render_as_string()}: {reason}"
        ) from None
    if revision is None:
        raise DatabaseNotReady(
            f"the database {url.render_as_string()} has no schema (not migrated): run "
            "`arena admin db upgrade`, or " + _WHERE
        )
    head = head_revision()
    if revision != head:
        raise DatabaseNotReady(
            f"the database is at migration {revision}, this version of arena expects {head}: "
            "run `arena admin db upgrade`"
        )
