"""Fixtures of the service tests: every database test runs twice, on SQLite with an in-memory
broker (the fast tier, ``pytest -m "not integration"``) and on PostgreSQL (a fresh database per
session, dropped at the end) with tasks on the shared Redis under a key prefix of this session,
removed at the end (``integration``, as in production)."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text

from arena.config import SandboxKind, Settings, get_settings
from arena.errors import SandboxUnavailable
from arena_command import app
from evaluator.sandbox import check_service_kind
from server.app import create_app
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import Base
from tests.cli_runner import CliRunner
from tests.server.builders import default_phases, write_suite
from tests.server.live import export_settings
from tests.settings import env_only

POSTGRES_ADMIN = "postgresql://postgres@127.0.0.1:5432/test"
REDIS_URL = "redis://127.0.0.1:6379/0"
ADMIN_TOKEN = "admin-secret-for-tests"


# psycopg and redis are imported where the integration tier uses them: the fast tier never does,
# and its every process would import them to collect (about 0.4 s of CPU each).


def _create_pg_database() -> tuple[str, str]:
    import psycopg

    name = f"arena_test_{uuid.uuid4().hex[:10]}"
    with psycopg.connect(POSTGRES_ADMIN, autocommit=True) as connection:
        connection.execute(f'CREATE DATABASE "{name}"')
    return name, f"postgresql+psycopg://postgres@127.0.0.1:5432/{name}"


def _drop_pg_database(name: str) -> None:
    import psycopg

    with psycopg.connect(POSTGRES_ADMIN, autocommit=True) as connection:
        connection.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


# The in-process broker of the fast tier: tasks sent are held in this process, never run.
MEMORY_BROKER = "memory://"


@pytest.fixture(
    scope="session",
    params=["sqlite", pytest.param("postgresql", marks=pytest.mark.integration)],
)
def database_url(request, tmp_path_factory) -> Iterator[str]:
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path_factory.mktemp('sqlite') / 'arena.db'}"
        upgrade_database(url)
        yield url
        return
    name, url = _create_pg_database()
    try:
        upgrade_database(url)
        yield url
    finally:
        _drop_pg_database(name)


@pytest.fixture(scope="session")
def broker_prefix() -> Iterator[str]:
    prefix = f"arena-test-{uuid.uuid4().hex[:8]}:"
    yield prefix
    import redis

    client = redis.Redis.from_url(REDIS_URL)
    keys = list(client.scan_iter(f"{prefix}*"))
    if keys:
        client.delete(*keys)


@pytest.fixture
def broker(request, database_url) -> tuple[str, str]:
    """(broker URL, key prefix): Redis beside PostgreSQL (production's pair), the in-memory
    broker beside SQLite (no server needed)."""
    if database_url.startswith("sqlite"):
        return MEMORY_BROKER, ""
    return REDIS_URL, request.getfixturevalue("broker_prefix")


@pytest.fixture
def suite_dir(tmp_path) -> Path:
    return write_suite(tmp_path / "suite", {"cruise": 2, "merge": 1})


@pytest.fixture(scope="session")
def fast_tier_sandbox() -> SandboxKind | None:
    """The sandbox of the fast tier's service: bubblewrap where it holds the service's sandbox
    contract, else (None) the service's own choice, Docker first. Both are real sandboxes, but
    Docker starts every validation and warm agent as a container through its daemon: over
    tests/server in one process that cost about 17 s of CPU in the daemon and the containers,
    outside pytest's, and 9 s of wall (2026-11-28). The integration tier keeps production's
    choice."""
    try:
        return check_service_kind(SandboxKind.bubblewrap, env_only().sandbox)
    except SandboxUnavailable:
        return None


@pytest.fixture
def settings(request, tmp_path, database_url, broker, suite_dir) -> Settings:
    url, prefix = broker
    fast_kind = request.getfixturevalue("fast_tier_sandbox") if url == MEMORY_BROKER else None
    return env_only(
        storage={"data_dir": tmp_path / "data", "database_url": database_url, "broker_url": url},
        sandbox={"kind": fast_kind} if fast_kind else {},
        service={
            "broker_key_prefix": prefix,
            "admin_token": ADMIN_TOKEN,
            "daily_quota": 3,
            "lease_seconds": 60,
        },
        suites={"hidden_suite_dir": suite_dir, "public_suite_dir": suite_dir},
        training={"train_dataset_dir": tmp_path / "dataset"},
    )


@pytest.fixture
def db(settings) -> Iterator[Database]:
    database = Database(settings.storage.database_url)
    yield database
    # Empty every table (children first) so the next test starts clean on the shared database,
    # then put back the default phases the migrations create.
    with database.session() as session:
        for table in reversed(Base.metadata.sorted_tables):
            session.execute(text(f"DELETE FROM {table.name}"))
        session.add_all(default_phases())
    database.dispose()


@pytest.fixture
def client(settings, db) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as test_client:
        yield test_client


@pytest.fixture
def arena(settings, db, monkeypatch):
    """`arena admin ...` configured like a deployment, through ARENA_* variables naming this
    test's database, broker and folders: ``arena("phases", "list")`` gives the output and
    checks the exit status (``ok=False``: it must fail)."""
    export_settings(monkeypatch, settings)
    get_settings.cache_clear()

    def invoke(*args: str, ok: bool = True) -> str:
        result = CliRunner().invoke(app, ["admin", *args])
        assert (result.exit_code == 0) == ok, result.output
        return result.output

    yield invoke
    get_settings.cache_clear()
