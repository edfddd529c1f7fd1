"""The Alembic migrations build exactly the schema of server.models, on SQLite and PostgreSQL."""

from __future__ import annotations

from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from server.core.migrate import current_revision, upgrade_database
from server.models import Base


def test_migrated_schema_matches_the_models(database_url):
    upgrade_database(database_url)  # idempotent on an up-to-date database
    assert current_revision(database_url) == "0002"
    from server.core.db import make_engine

    engine = make_engine(database_url)
    with engine.connect() as connection:
        context = MigrationContext.configure(connection, opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
    engine.dispose()
