"""`arena serve` with several uvicorn workers, configured as the compose file configures the API:
a password-free database URL and the password in a secret file."""

from __future__ import annotations

import time

import httpx
import pytest

from server.core.migrate import upgrade_database
from tests.server.conftest import _create_pg_database, _drop_pg_database
from tests.server.live import ARENA, environment, free_port, start, stop
from tests.settings import env_only

pytestmark = pytest.mark.integration


def test_every_uvicorn_worker_reads_the_database_url_beside_its_password_file(tmp_path):
    """The URL is a secret's plain variable, which get_settings() withdraws from its process's
    environment: read in `arena serve` itself, it was gone from the workers' environment, who
    found the password file without it and stopped (the service image's API never answered)."""
    name, url = _create_pg_database()
    try:
        upgrade_database(url)
        password = tmp_path / "postgres_password"
        password.write_text("unused: the test server trusts local connections\n")
        settings = env_only(storage={"data_dir": tmp_path / "data", "database_url": url})
        env = environment(settings, ARENA_DATABASE_PASSWORD_FILE=str(password))
        port = free_port()
        command = [*ARENA, "serve", "--port", str(port), "--workers", "2"]
        server = start(command, env, tmp_path / "serve.log")
        try:
            deadline = time.monotonic() + 120
            answered = None
            while answered is None and server.poll() is None and time.monotonic() < deadline:
                try:
                    answered = httpx.get(f"http://127.0.0.1:{port}/api/v1/healthz", timeout=2)
                except httpx.HTTPError:
                    time.sleep(0.5)
        finally:
            stop(server)
        log = (tmp_path / "serve.log").read_text(errors="replace")
        assert answered is not None and answered.status_code == 200, log[-3000:]
        assert "without a URL" not in log
    finally:
        _drop_pg_database(name)
