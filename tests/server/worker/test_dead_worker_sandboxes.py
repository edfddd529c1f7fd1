"""A worker that starts removes what worker processes of its host that died left: their scratch
and the Docker containers that bind it. A container outlives the process that started it, so a
SIGKILLed worker's intake sandbox stayed, stopped, for good (the fault campaign's one leftover)."""

from __future__ import annotations

import os
import socket

import pytest

from arena.config import get_settings
from evaluator.sandbox.backend import SANDBOX_LABEL, owner_labels
from evaluator.sandbox.docker_backend import docker_client
from server.worker import local, tasks
from tests.server.live import export_settings

pytestmark = [pytest.mark.docker, pytest.mark.integration]

DEAD_PID = 4_194_304  # above the kernel's largest pid: never a live process


@pytest.fixture
def worker_settings(settings, monkeypatch):
    export_settings(monkeypatch, settings)
    get_settings.cache_clear()
    yield get_settings()
    get_settings.cache_clear()


def sandbox_binding(folder, labels: dict[str, str]):
    """A created (never started) sandbox container binding ``folder``."""
    folder.mkdir(parents=True)
    return docker_client().containers.create(
        get_settings().sandbox.agent_image,
        command=["true"],
        labels=labels,
        volumes={str(folder): {"bind": "/submission", "mode": "ro"}},
        network_disabled=True,
    )


def exists(container) -> bool:
    return any(c.id == container.id for c in docker_client().containers.list(all=True))


def test_a_dead_workers_containers_go_with_its_scratch(worker_settings):
    data_dir = worker_settings.storage.resolved_data_dir
    ours = {SANDBOX_LABEL: "1", **owner_labels(data_dir)}
    host = socket.gethostname()
    dead = data_dir / "scratch" / f"{host}-{DEAD_PID}"
    live = data_dir / "scratch" / f"{host}-{os.getpid()}"
    left = sandbox_binding(dead / "submissions" / "abc" / "prepared", ours)
    running = sandbox_binding(live / "submissions" / "abc" / "prepared", ours)
    try:
        assert local.orphan_scratch() == [dead]
        tasks._remove_orphan_scratch()
        assert not dead.exists() and live.is_dir()
        assert not exists(left)
        assert exists(running)  # a live worker's
    finally:
        for container in (left, running):
            if exists(container):
                container.remove(force=True)
