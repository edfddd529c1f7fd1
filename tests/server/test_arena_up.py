"""`arena up`, the README's run command: migrates, starts API and worker, prints the URL and a
demo token; Ctrl-C stops everything."""

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


def test_arena_up_serves_and_stops_cleanly(tmp_path):
    root = shared_dir("arena-up-")
    suite = build_small_suite(root)
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ARENA_")}
    env |= {
        "ARENA_DATA_DIR": str(root / "data"),
        "ARENA_HIDDEN_SUITE_DIR": str(suite),
        "ARENA_PUBLIC_SUITE_DIR": str(suite),
        "ARENA_SANDBOX": "bubblewrap",
        "COLUMNS": "200",
    }
    log = tmp_path / "up.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [*ARENA, "up", "--port", str(port)],
            env=env,
            stdout=out,
            stderr=out,
            start_new_session=True,
        )
    try:
        deadline = time.monotonic() + 90
        while "is up at" not in log.read_text():
            assert process.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.3)
        text = log.read_text()
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
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=40) == 0
        with pytest.raises(httpx.ConnectError):
            httpx.get(f"{url}/api/v1/healthz", timeout=2)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        shutil.rmtree(root, ignore_errors=True)
