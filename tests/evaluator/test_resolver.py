"""The resolver sandbox: its only way out reaches the package index and nothing else, and the
child the service spawns holds no secret in its environment or arguments."""

from __future__ import annotations

import http.client
import json
import shutil
import socket
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from agent_runtime import resolve
from arena.config import SandboxKind, Settings
from arena.errors import IntakeError
from bench._package_index import build_wheel, served_index
from evaluator.resolver import (
    PROXY_SOCKET,
    host_pip,
    pip_ca_bundle,
    run_resolver,
    spawn_resolver,
)
from evaluator.sandbox.docker_backend import COPIES_DIR
from evaluator.sandbox.index_proxy import IndexProxy
from evaluator.sandbox.subprocess_sandbox import labelled_pids
from evaluator.validation import validate
from tests.evaluator.sandbox.conftest import usable
from tests.settings import with_fields
from tests.submissions.zips import with_policy, write_zip

SECRET = "s3cret-admin-token-9b2e"


@pytest.fixture
def two_servers(tmp_path: Path) -> Iterator[tuple[str, str]]:
    """The package index and another server on loopback (what the sandbox must not reach)."""
    for name in ("index", "other"):
        (tmp_path / f"{name}-files").mkdir()
        build_wheel(tmp_path / f"{name}-files", f"{name}pkg", "1.0")
    with (
        served_index(tmp_path / "index-files", tmp_path / "index") as index,
        served_index(tmp_path / "other-files", tmp_path / "other") as other,
    ):
        yield index, other


def proxied(socket_path: Path, request: bytes) -> bytes:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as client:
        client.connect(str(socket_path))
        client.sendall(request)
        data = b""
        while chunk := client.recv(65536):
            data += chunk
            if request.startswith(b"CONNECT"):
                break
    return data


def test_the_index_proxy_reaches_the_index_and_nothing_else(
    tmp_path: Path, two_servers: tuple[str, str]
) -> None:
    index, other = two_servers
    index_port = int(index.split(":")[2].split("/")[0])
    other_port = int(other.split(":")[2].split("/")[0])
    with IndexProxy(tmp_path / PROXY_SOCKET, {("127.0.0.1", index_port)}) as proxy:
        page = proxied(
            proxy.socket_path,
            f"GET {index}/indexpkg/ HTTP/1.1\r\nHost: x\r\nConnection: keep-alive\r\n\r\n".encode(),
        )
        assert page.startswith(b"HTTP/1.0 200") and b"indexpkg-1.0" in page
        refused = proxied(proxy.socket_path, f"GET {other}/otherpkg/ HTTP/1.1\r\n\r\n".encode())
        assert refused.startswith(b"HTTP/1.1 403")
        connect = f"CONNECT 127.0.0.1:{other_port} HTTP/1.1\r\n\r\n"
        tunnel = proxied(proxy.socket_path, connect.encode())
        assert tunnel.startswith(b"HTTP/1.1 403")
        assert proxy.refused == [f"{other}/otherpkg/", f"127.0.0.1:{other_port}"]


def test_a_proxied_request_carries_one_request_per_connection(
    tmp_path: Path, two_servers: tuple[str, str]
) -> None:
    """A second request on the same connection could name another host: the proxy closes."""
    index, _ = two_servers
    port = int(index.split(":")[2].split("/")[0])
    with (
        IndexProxy(tmp_path / PROXY_SOCKET, {("127.0.0.1", port)}) as proxy,
        socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as client,
    ):
        client.connect(str(proxy.socket_path))
        connection = http.client.HTTPConnection("127.0.0.1")
        connection.sock = client
        connection.request("GET", f"{index}/indexpkg/", headers={"Connection": "keep-alive"})
        response = connection.getresponse()
        assert response.status == 200 and response.will_close
        response.read()


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_the_resolver_child_holds_no_secret_in_its_environment_or_arguments(
    tmp_path: Path, two_servers: tuple[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Spawned by the one function that starts it (spawn_resolver), while the parent holds the
    admin token in its environment: every process of the sandbox is read from /proc."""
    monkeypatch.setenv("ARENA_ADMIN_TOKEN", SECRET)
    index, _ = two_servers
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    inputs, output, program = tmp_path / "in", tmp_path / "out", tmp_path / "program"
    for folder in (inputs, program):
        folder.mkdir()
    request = {
        "requirements": [[1, "indexpkg==1.0"]],
        "index_urls": [index],
        "find_links": [],
        "target": [],
        "constraints": [],
    }
    (inputs / resolve.REQUEST).write_text(json.dumps(request))
    labels = {"arena.test": uuid.uuid4().hex}
    box = spawn_resolver(
        "build",  # no sdists to build: the child starts, looks and ends
        inputs,
        output,
        program,
        intake=settings.intake,
        config=settings.sandbox,
        data_dir=settings.storage.resolved_data_dir,
        kind="bubblewrap",
        labels=labels,
    )
    seen: dict[int, bytes] = {}
    try:
        deadline = time.monotonic() + 60
        while box.exit_status(0.01) is None and time.monotonic() < deadline:
            for pid in labelled_pids(labels):
                try:
                    environ = Path(f"/proc/{pid}/environ").read_bytes()
                    argv = Path(f"/proc/{pid}/cmdline").read_bytes()
                except OSError:
                    continue
                seen[pid] = environ + b"\0" + argv
    finally:
        box.kill()
    assert seen, "no process of the resolver sandbox was seen"
    assert not [pid for pid, text in seen.items() if SECRET.encode() in text]
    assert not [pid for pid, text in seen.items() if b"ARENA_ADMIN_TOKEN" in text]


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_the_resolver_is_bounded_in_time(tmp_path: Path) -> None:
    """An index that takes connections and never answers (a real one could let pip finish
    within a short bound on a quiet machine): the step ends at its wall time."""
    settings = with_fields(
        Settings(), storage={"data_dir": tmp_path / "data"}, intake={"resolver_timeout_s": 0.5}
    )
    (tmp_path / "in").mkdir()
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(16)  # connections complete in the backlog; none is ever accepted
        index = f"http://127.0.0.1:{silent.getsockname()[1]}/simple/"
        request = {"requirements": [[1, "indexpkg==1.0"]], "index_urls": [index], "find_links": []}
        (tmp_path / "in" / resolve.REQUEST).write_text(json.dumps(request))
        started = time.monotonic()
        with pytest.raises(IntakeError) as caught:
            run_resolver(
                "download",
                tmp_path / "in",
                tmp_path / "out",
                intake=settings.intake,
                config=settings.sandbox,
                data_dir=settings.storage.resolved_data_dir,
                kind="bubblewrap",
            )
    assert caught.value.rule == "resolver-timeout"
    assert time.monotonic() - started < 30


@pytest.mark.docker
@pytest.mark.slow  # the resolver and the upload's validation in Docker
def test_a_docker_resolver_of_a_worker_with_a_shared_folder_installs_from_its_wheel_folder(
    tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    """The compose worker's case (its image's /wheels, docs/deployment.md): the wheel folder and
    pip are outside the data folder, so the containers bind their copies in the shared folder,
    which the sandbox's uid reads."""
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    # Short: the index proxy's socket is made in it (AF_UNIX paths are short).
    shared = Path(tempfile.mkdtemp(prefix="arena-shared-"))
    request.addfinalizer(lambda: shutil.rmtree(shared))
    build_wheel(wheels, "wheelpkg", "1.0")
    settings = with_fields(
        Settings(),
        storage={"data_dir": tmp_path / "data"},
        intake={"package_index": [str(wheels)]},
        sandbox={"sandbox_shared_dir": shared},
    )
    usable(SandboxKind.docker, settings)
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"requirements.txt": "wheelpkg==1.0\n"}))
    prepared = validate(
        upload,
        tmp_path / "a",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        kind=SandboxKind.docker,
    )
    assert prepared.deps_dir is not None
    assert (prepared.deps_dir / "wheelpkg" / "__init__.py").is_file()
    copies = {path.name.rsplit("-", 1)[0] for path in (shared / COPIES_DIR).iterdir()}
    assert {"wheels", "pip", "agent_runtime"} <= copies


def test_a_pip_whose_ca_bundle_lies_outside_it_has_the_bundle_bound(tmp_path: Path) -> None:
    """Debian's pip reads the system's bundle, which the sandbox lacks: pip there stopped at the
    first HTTPS index ("Could not find a suitable TLS CA certificate bundle"). This pip's own
    bundle is inside it; for a pip folder without it, the bundle is named, as a cert would be."""
    from pip._vendor import certifi

    assert pip_ca_bundle(host_pip()) is None
    assert pip_ca_bundle(tmp_path / "pip") == str(Path(certifi.where()).resolve())
