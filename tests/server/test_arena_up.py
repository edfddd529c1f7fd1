"""`arena up`, the README's run command: migrates, starts API and worker, prints the URL and a
demo token; Ctrl-C stops everything; its children die with it whatever kills it; one instance
per data folder; the demo token survives restarts."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time

import httpx
import pytest

from tests.server.live import ARENA, free_port
from tests.server.service_stack import build_small_suite, shared_dir

pytestmark = [pytest.mark.slow, pytest.mark.bwrap]


@pytest.fixture(scope="module")
def root():
    folder = shared_dir("arena-up-")
    build_small_suite(folder)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def up_env(root) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("ARENA_")}
    return env | {
        "ARENA_DATA_DIR": str(root / "data"),
        "ARENA_HIDDEN_SUITE_DIR": str(root / "suite"),
        "ARENA_PUBLIC_SUITE_DIR": str(root / "suite"),
        "ARENA_SANDBOX": "bubblewrap",
        "COLUMNS": "200",
    }


def start_up(root, port: int, log) -> subprocess.Popen:
    with log.open("wb") as out:
        return subprocess.Popen(
            [*ARENA, "up", "--port", str(port)],
            env=up_env(root),
            stdout=out,
            stderr=out,
            start_new_session=True,
            # As a background job of a script starts it: Ctrl-C must stop it all the same.
            preexec_fn=_ignore_sigint,
        )


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def wait_up(process: subprocess.Popen, log) -> str:
    deadline = time.monotonic() + 90
    while "is up at" not in log.read_text():
        assert process.poll() is None, log.read_text()
        assert time.monotonic() < deadline, log.read_text()
        time.sleep(0.3)
    return log.read_text()


def answers(url: str) -> bool:
    try:
        return httpx.get(f"{url}/api/v1/healthz", timeout=2).status_code == 200
    except httpx.HTTPError:
        return False


def test_arena_up_serves_and_stops_cleanly(root, tmp_path):
    port = free_port()
    log = tmp_path / "up.log"
    process = start_up(root, port, log)
    try:
        text = wait_up(process, log)
        token = re.search(r"team demo token: (arena_\S+)", text).group(1)
        admin = re.search(r"admin token: (\S+)", text).group(1)
        url = f"http://127.0.0.1:{port}"
        assert httpx.get(f"{url}/api/v1/healthz").status_code == 200
        mine = httpx.get(f"{url}/api/v1/submissions", headers={"Authorization": f"Bearer {token}"})
        assert mine.status_code == 200
        listing = httpx.get(
            f"{url}/api/v1/admin/submissions", headers={"Authorization": f"Bearer {admin}"}
        )
        assert listing.status_code == 200
        assert (root / "data" / "arena.db").exists()
        # Closed to the agents' uid: the database, uploads and the hidden suite are in it.
        assert (root / "data").stat().st_mode & 0o007 == 0  # nothing for other users
        process.send_signal(signal.SIGINT)
        # Its children get one shared grace (15 s) and are killed after it.
        try:
            assert process.wait(timeout=40) == 0, log.read_text()
        except subprocess.TimeoutExpired:
            pytest.fail(f"arena up did not stop within 40 s of Ctrl-C:\n{log.read_text()}")
        with pytest.raises(httpx.ConnectError):
            httpx.get(f"{url}/api/v1/healthz", timeout=2)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)


def test_one_instance_per_data_folder_children_die_with_it_token_stays(root, tmp_path):
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    first = start_up(root, port, tmp_path / "first.log")
    processes = [first]
    try:
        token = re.search(r"token: (arena_\S+)", wait_up(first, tmp_path / "first.log")).group(1)
        # A second instance on the same data folder (another port) is refused, and the first
        # keeps serving.
        second = subprocess.run(
            [*ARENA, "up", "--port", str(free_port())],
            env=up_env(root),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert second.returncode == 1
        assert "already served by `arena up`" in second.stdout + second.stderr
        assert answers(url)
        # SIGKILL of `arena up` alone: its API and worker go with it.
        first.kill()
        first.wait()
        deadline = time.monotonic() + 40
        while answers(url):
            assert time.monotonic() < deadline, "the API outlived `arena up`"
            time.sleep(0.5)
        again = start_up(root, port, tmp_path / "again.log")
        processes.append(again)
        text = wait_up(again, tmp_path / "again.log")
        assert re.search(r"token: (arena_\S+)", text).group(1) == token
        assert (
            httpx.get(
                f"{url}/api/v1/submissions", headers={"Authorization": f"Bearer {token}"}
            ).status_code
            == 200
        )
        again.send_signal(signal.SIGTERM)
        assert again.wait(timeout=40) == 0
    finally:
        for process in processes:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)


def test_a_port_with_a_listener_is_refused_one_without_is_free():
    import socket

    from server.embedded import AlreadyServed, _check_port_free

    with socket.socket() as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        with pytest.raises(AlreadyServed, match=f"port {port} on 127.0.0.1 is already in use"):
            _check_port_free("127.0.0.1", port)
    _check_port_free("127.0.0.1", port)
