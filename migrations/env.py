"""Alembic environment: one metadata (server.models), URL from the caller or the settings."""

from __future__ import annotations

from alembic import context
from sqlalchemy import TypeDecorator

from arena.config import get_settings
from server.core.db import make_engine
from server.models import Base

config = context.config
target_metadata = Base.metadata


def _url() -> str:
    url = config.get_main_option("sqlalchemy.url")
    if url:
        return url
    return get_settings().storage.resolved_database_url


def render_item(type_: str, obj, autogen_context):
    """Write our column types as their plain SQLAlchemy type: migrations must not import models."""
    if type_ == "type" and isinstance(obj, TypeDecorator):
        return f"sa.{obj.impl!r}"
    return False


def run_migrations_offline() -> None:
    context.configure(
        url=_url(), target_metadata=target_metadata, render_as_batch=True, render_item=render_item
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    engine = make_engine(_url())
    with engine.connect() as connection:
        if connection.dialect.name == "sqlite":
            # Batch mode rebuilds a table by dropping it, which the foreign keys of the rows
            # pointing at it would refuse (SQLite ignores this pragma inside a transaction).
            connection.connection.driver_connection.execute("PRAGMA foreign_keys=OFF")
        # Batch mode so ALTERs work on SQLite too (it rebuilds the table).
        context.configure(
            connection=connection,
            target_metadata=target_metadata,
            render_as_batch=True,
            render_item=render_item,
        )
        with context.begin_transaction():
            context.run_migrations()
    engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
