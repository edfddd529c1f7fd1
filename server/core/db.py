"""Engine and session factories for a database URL.

SQLite (the embedded default) runs in WAL mode with every transaction ``BEGIN IMMEDIATE``: the API
and several worker processes write the same file, and taking the write lock up front makes a
read-then-update (status checks, quotas) safe and turns contention into waiting rather than
``database is locked`` errors. PostgreSQL uses row locks (``SELECT ... FOR UPDATE``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.orm import Session, sessionmaker


def make_engine(url: str, *, read_only: bool = False) -> Engine:
    """An engine for ``url``. On SQLite, ``read_only`` engines begin deferred transactions (WAL
    readers never wait for writers); the others take the write lock up front."""
    if not url.startswith("sqlite"):
        return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)
    path = url.removeprefix("sqlite:///")
    if path and path != ":memory:":
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    engine = create_engine(url, connect_args={"timeout": 60, "check_same_thread": False})

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection, _record) -> None:
        # Let SQLAlchemy (not the sqlite3 module) decide when transactions begin.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute("PRAGMA busy_timeout=60000")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection) -> None:
        connection.exec_driver_sql("BEGIN" if read_only else "BEGIN IMMEDIATE")

    return engine


class Database:
    """An engine and its session factory. One per process (the API's app state, the worker's
    :func:`server.worker.local.database`)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.engine = make_engine(url)
        self.sessions = sessionmaker(self.engine, expire_on_commit=False)
        self.read_engine = (
            make_engine(url, read_only=True) if url.startswith("sqlite") else self.engine
        )
        self.read_sessions = sessionmaker(self.read_engine, expire_on_commit=False)

    @contextmanager
    def session(self) -> Iterator[Session]:
        """A session whose transaction commits on success and rolls back on error."""
        with self.sessions() as session, session.begin():
            yield session

    @contextmanager
    def read_session(self) -> Iterator[Session]:
        """A session for reading only (request handlers' lookups): never blocks on writers."""
        with self.read_sessions() as session, session.begin():
            yield session

    def dispose(self, *, close: bool = True) -> None:
        self.engine.dispose(close=close)
        self.read_engine.dispose(close=close)

    def after_fork(self) -> None:
        """Drop connections inherited from a parent process (Celery prefork children)."""
        self.dispose(close=False)
