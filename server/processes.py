"""The service as real processes, for the end-to-end tests and the benchmarks (never imported by
the service itself): the API and Celery workers configured by ARENA_* variables, started and
stopped by pid; a small suite of public scenarios; uploads through the REST API."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

from arena.config import Settings
from arena.examples import examples_dir

ARENA = [sys.executable, "-c", "from arena_command import app; app()"]
EXAMPLES = examples_dir()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def environment(settings: Settings, **extra: str) -> dict[str, str]:
    """The settings as ARENA_* variables for a child process."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ARENA_")}
    for group in Settings.model_fields:
        fields = getattr(settings, group)
        for name, variable in fields.env_names().items():
            value = getattr(fields, name)
            if value is not None:
                env[variable] = str(value.value if hasattr(value, "value") else value)
    env.update(extra)
    return env


def start(command: list[str], env: dict[str, str], log_path) -> subprocess.Popen:
    log = open(log_path, "ab")  # noqa: SIM115  (kept open for the child's lifetime)
    return subprocess.Popen(command, env=env, stdout=log, stderr=log, start_new_session=True)


def stop(process: subprocess.Popen, sig: int = signal.SIGTERM, timeout_s: float = 30) -> None:
    if process.poll() is None:
        os.killpg(process.pid, sig)
        try:
            process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


@contextmanager
def api_server(settings: Settings, log_path) -> Iterator[tuple[str, subprocess.Popen]]:
    port = free_port()
    process = start(
        [*ARENA, "serve", "--host", "127.0.0.1", "--port", str(port)],
        environment(settings),
        log_path,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{url}/api/v1/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"API did not start, see {log_path}")
            time.sleep(0.2)
        yield url, process
    finally:
        stop(process)


def peak_rss_bytes(pid: int) -> int:
    """High-water mark of the process's resident memory."""
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM")


# Where the three example agents differ: planner completes all, keep_lane fails the merge,
# random fails three.
SCENARIOS = (
    "p000_left_turn_t_low",
    "p009_merge_2lane_low",
    "p016_cruise_2lane_low",
    "p023_overtake_2lane_low",
    "p030_replay_cruise",
)
FINISHED = {"scored", "failed", "rejected", "cancelled", "disqualified"}


def shared_dir(prefix: str) -> Path:
    """A folder the sandbox user (uid 65534) may enter, unlike pytest's private tmp_path."""
    path = Path(tempfile.mkdtemp(prefix=prefix))
    path.chmod(0o755)
    return path


def build_small_suite(root: Path) -> Path:
    """The public suite built once, cut down to :data:`SCENARIOS`."""
    full = root / "public-full"
    subprocess.run(
        [*ARENA, "scenarios", "build", "--suite", "public", "--out", str(full)],
        check=True,
        capture_output=True,
    )
    return cut_suite(full, root / "suite")


def cut_suite(full: Path, small: Path) -> Path:
    """A copy of the suite folder ``full`` with only :data:`SCENARIOS`, in ``small``."""
    manifest = json.loads((full / "manifest.json").read_text())
    manifest["scenarios"] = [s for s in manifest["scenarios"] if s["id"] in SCENARIOS]
    if len(manifest["scenarios"]) != len(SCENARIOS):
        raise ValueError(f"{full} lacks some of {SCENARIOS}")
    small.mkdir()
    for scenario in SCENARIOS:
        shutil.copytree(full / scenario, small / scenario)
    (small / "manifest.json").write_text(json.dumps(manifest))
    return small


def start_worker(settings: Settings, log_path: Path, concurrency: int = 2) -> subprocess.Popen:
    return start(
        [*ARENA, "worker", "--concurrency", str(concurrency), "--loglevel", "INFO"],
        environment(settings),
        log_path,
    )


def upload_folder(url: str, token: str, folder: Path, zips: Path) -> int:
    """Pack the agent ``folder`` into ``zips`` and upload it; the submission's id."""
    from submissions.intake import pack_folder

    name = folder.name
    path = pack_folder(folder, zips / f"{name}.zip")
    with path.open("rb") as handle:
        response = httpx.post(
            f"{url}/api/v1/submissions",
            headers=bearer(token),
            data={"track": "freestyle", "method_name": name, "description": f"example {name}"},
            files={"file": (path.name, handle, "application/zip")},
            timeout=120,
        )
    # Received and stored; the worker validates it, then evaluates it.
    if response.status_code != 202:
        raise RuntimeError(f"upload of {name} refused: {response.status_code} {response.text}")
    return response.json()["id"]


def wait_finished(url: str, token: str, submission_id: int, timeout_s: float = 240) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        body = httpx.get(
            f"{url}/api/v1/submissions/{submission_id}", headers=bearer(token), timeout=10
        ).json()
        if body["status"] in FINISHED:
            return body
        if time.monotonic() > deadline:
            raise TimeoutError(f"submission {submission_id} did not finish: {body}")
        time.sleep(1)


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}
