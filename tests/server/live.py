"""Real service processes for the tests: uvicorn and Celery workers configured by environment
variables, started and stopped by pid."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import httpx

from arena.config import Settings

ARENA = [sys.executable, "-c", "from arena.cli import app; app()"]


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


def export_settings(monkeypatch, settings: Settings) -> None:
    """The settings as this process's ARENA_* variables, as :func:`environment` gives a child:
    the process then reads them as ``arena`` commands and workers do (clear ``get_settings``)."""
    for name in [name for name in os.environ if name.startswith("ARENA_")]:
        monkeypatch.delenv(name)
    for name, value in environment(settings).items():
        if name.startswith("ARENA_"):
            monkeypatch.setenv(name, value)


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
