"""A worker in a container (docker-compose.yml) starts agents beside it through the host's
daemon, which binds host paths: with ARENA_SANDBOX_SHARED_DIR the runtime and the sockets live
in that folder, whose path is the same on both sides. The compose deployment test
(tests/server/test_compose_deployment.py) runs agents that way."""

from __future__ import annotations

import tempfile
from pathlib import Path

from evaluator.sandbox.backend import RUNTIME_MAIN, runtime_dir
from evaluator.sandbox.docker_backend import runtime_source, socket_dir_for
from tests.settings import env_only


def test_the_runtime_and_the_sockets_go_to_the_shared_folder(tmp_path):
    shared = tmp_path / "shared"
    settings = env_only(sandbox={"sandbox_shared_dir": shared})
    shared.mkdir()
    copy = runtime_source(settings.sandbox.sandbox_shared_dir)
    assert copy.parent == shared
    package = runtime_dir()
    for path in package.rglob("*.py"):
        if "__pycache__" not in path.parts:
            assert (copy / path.relative_to(package)).read_bytes() == path.read_bytes()
    assert (copy / RUNTIME_MAIN).stat().st_mode & 0o777 == 0o644
    assert runtime_source(settings.sandbox.sandbox_shared_dir) == copy  # one copy per content
    assert [p.name for p in shared.iterdir()] == [copy.name]  # no partial copy left
    assert socket_dir_for("abc", settings.sandbox.sandbox_shared_dir).parent == shared


def test_without_a_shared_folder_the_package_and_the_temporary_folder_serve(tmp_path):
    settings = env_only()
    assert runtime_source(settings.sandbox.sandbox_shared_dir) == runtime_dir()
    assert socket_dir_for("abc", settings.sandbox.sandbox_shared_dir).parent == Path(
        tempfile.gettempdir()
    )
