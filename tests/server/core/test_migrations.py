"""The Alembic migrations build exactly the schema of server.models, on SQLite and PostgreSQL."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import text

from server.core.db import make_engine
from server.core.migrate import alembic_config, current_revision, head_revision, upgrade_database
from server.models import Base
from tests.server.conftest import _create_pg_database, _drop_pg_database


def test_migrated_schema_matches_the_models(database_url):
    upgrade_database(database_url)  # idempotent on an up-to-date database
    assert current_revision(database_url) == head_revision()
    engine = make_engine(database_url)
    with engine.connect() as connection:
        context = MigrationContext.configure(connection, opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
    engine.dispose()


def test_old_scenario_statuses_move_to_the_core_vocabulary(tmp_path):
    """Migration 0002: rows written with the service's old statuses read as the core's."""
    url = f"sqlite:///{tmp_path / 'old.db'}"
    upgrade_database(url, "0001")
    engine = make_engine(url)
    with engine.begin() as connection:
        connection.execute(
            text("INSERT INTO teams (id, name, created_at) VALUES (1, 't', '2026-01-01');")
        )
        connection.execute(
            text(
                "INSERT INTO submissions (id, team_id, track, method_name, description,"
                " file_sha256, file_size, storage_dir, status, status_reason, created_at)"
                " VALUES (1, 1, 'freestyle', 'm', '', 'x', 1, '/data/submissions/d', 'scored', '',"
                " '2026-01-01')"
            )
        )
        connection.execute(
            text(
                "INSERT INTO evaluation_runs (id, submission_id, attempt, status, suite_dir,"
                " manifest_sha256, scenario_count, scoring_profile, scoring_version, worker,"
                " created_at, error) VALUES (1, 1, 1, 'scored', 's', 'h', 3, 'p', '1', '',"
                " '2026-01-01', '')"
            )
        )
        for i, status in enumerate(("success", "failure", "infrastructure_error")):
            connection.execute(
                text(
                    "INSERT INTO scenario_results (run_id, scenario_id, family, status, reason,"
                    " steps, log_tail, detail, worker, attempts, created_at) VALUES"
                    f" (1, 's{i}', 'cruise', '{status}', '', 0, '', '{{}}', '', 1, '2026-01-01')"
                )
            )
    upgrade_database(url)
    with engine.connect() as connection:
        statuses = connection.execute(
            text("SELECT status FROM scenario_results ORDER BY scenario_id")
        ).scalars()
        assert list(statuses) == ["done", "done", "evaluator_error"]
        phase, upload = connection.execute(text("SELECT phase, upload_key FROM submissions")).one()
        assert (phase, upload) == ("final", "submissions/d/upload.zip")
    engine.dispose()


def test_episodes_migration_keeps_runs_and_results_and_goes_back(tmp_path):
    """Migration 0008: a run's scenario count becomes its episode count,
    every existing result is episode 0, old scores have no interval; the downgrade keeps first
    episodes only."""
    url = f"sqlite:///{tmp_path / 'old.db'}"
    upgrade_database(url, "0007")
    engine = make_engine(url)
    with engine.begin() as connection:
        connection.execute(text("INSERT INTO teams (id, name, created_at) VALUES (1, 't', '2026')"))
        connection.execute(
            text(
                "INSERT INTO submissions (id, team_id, phase, track, method_name, description,"
                " file_sha256, file_size, upload_key, status, status_reason, created_at)"
                " VALUES (1, 1, 'final', 'freestyle', 'm', '', 'x', 1, 'k', 'scored', '', '2026')"
            )
        )
        connection.execute(
            text(
                "INSERT INTO evaluation_runs (id, submission_id, attempt, status, suite_dir,"
                " manifest_sha256, scenario_count, scoring_profile, scoring_version, worker,"
                " created_at, error) VALUES (1, 1, 1, 'scored', 's', 'h', 2, 'p', '1', '',"
                " '2026', '')"
            )
        )
        for sid in ("a", "b"):
            connection.execute(
                text(
                    "INSERT INTO scenario_results (run_id, scenario_id, family, status, reason,"
                    " steps, log_tail, detail, worker, attempts, created_at) VALUES"
                    f" (1, '{sid}', 'cruise', 'done', '', 0, '', '{{}}', '', 1, '2026')"
                )
            )
        connection.execute(
            text(
                "INSERT INTO scores (run_id, completion, time, families, profile,"
                " profile_version, computed_at) VALUES (1, 0.5, 400, '{}', 'p', '1', '2026')"
            )
        )
    upgrade_database(url)
    with engine.begin() as connection:
        run = connection.execute(
            text("SELECT episode_count, episodes_per_scenario FROM evaluation_runs")
        ).one()
        assert tuple(run) == (2, 1)
        episodes = connection.execute(text("SELECT episode FROM scenario_results")).scalars()
        assert list(episodes) == [0, 0]
        interval = connection.execute(text("SELECT completion_low FROM scores")).scalar()
        assert interval is None
        # A second episode of a scenario is a row of its own now.
        connection.execute(
            text(
                "INSERT INTO scenario_results (run_id, scenario_id, episode, family, status,"
                " reason, steps, log_tail, detail, worker, claim_number, created_at) VALUES"
                " (1, 'a', 1, 'cruise', 'done', '', 0, '', '{}', '', 1, '2026')"
            )
        )
    command.downgrade(alembic_config(url), "0007")
    with engine.connect() as connection:
        rows = connection.execute(text("SELECT scenario_id FROM scenario_results")).scalars()
        assert sorted(rows) == ["a", "b"]
        count = connection.execute(text("SELECT scenario_count FROM evaluation_runs")).scalar()
        assert count == 2
    engine.dispose()


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.integration)])
def empty_database_url(request, tmp_path) -> Iterator[str]:
    """A database of its own, not migrated yet (the shared one must stay at the head)."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'old.db'}"
        return
    name, url = _create_pg_database()
    try:
        yield url
    finally:
        _drop_pg_database(name)


# Each job table's fence token before migration 0019, and the value the test's row holds.
OLD_FENCE_TOKENS = {
    "scenario_results": ("attempts", 2),
    "training_jobs": ("claims", 3),
    "upload_validations": ("claims", 1),
}


def test_fence_tokens_keep_their_values_under_one_name_and_go_back(empty_database_url):
    """Migration 0019: ``attempts`` and ``claims`` become ``claim_number`` with every row's
    value, and the downgrade gives them their old names back."""
    url = empty_database_url
    upgrade_database(url, "0018")
    engine = make_engine(url)
    moment = "2026-01-01 00:00:00+00"
    with engine.begin() as connection:
        for statement in (
            "INSERT INTO teams (id, name, created_at) VALUES (1, 't', :moment)",
            "INSERT INTO submissions (id, team_id, phase, track, method_name, description,"
            " file_sha256, file_size, upload_key, status, status_reason, created_at) VALUES"
            " (1, 1, 'final', 'offline', 'm', '', 'x', 1, 'k', 'running', '', :moment)",
            "INSERT INTO evaluation_runs (id, submission_id, attempt, status, suite_dir,"
            " manifest_sha256, episode_count, scoring_profile, scoring_version, worker,"
            " created_at, error) VALUES (1, 1, 1, 'running', 's', 'h', 1, 'p', '1', '', :moment,"
            " '')",
            "INSERT INTO scenario_results (run_id, scenario_id, family, status, reason, steps,"
            " log_tail, detail, worker, attempts, created_at) VALUES (1, 's', 'cruise',"
            " 'running', '', 0, '', '{}', 'w', 2, :moment)",
            "INSERT INTO training_jobs (submission_id, attempt, status, worker, claims,"
            " created_at, elapsed_s, log_tail, failure, error, model_sha256, model_size) VALUES"
            " (1, 1, 'training', 'w', 3, :moment, 0, '', '', '', '', 0)",
            "INSERT INTO upload_validations (submission_id, worker, claims, created_at) VALUES"
            " (1, 'w', 1, :moment)",
        ):
            connection.execute(text(statement), {"moment": moment})
    upgrade_database(url)
    with engine.connect() as connection:
        for table, (_, value) in OLD_FENCE_TOKENS.items():
            assert connection.execute(text(f"SELECT claim_number FROM {table}")).scalar() == value
    command.downgrade(alembic_config(url), "0018")
    with engine.connect() as connection:
        for table, (old, value) in OLD_FENCE_TOKENS.items():
            assert connection.execute(text(f"SELECT {old} FROM {table}")).scalar() == value
    engine.dispose()
