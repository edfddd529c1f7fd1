"""docker-compose.yml keeps every secret in a file and is hardened (docs/deployment.md): no
secret in any service's environment or command line, each secret file declared where it is read,
the API on loopback, no group 0, pulled images pinned by digest, limits on the API and workers,
and the Docker socket only in a worker whose sandboxes are containers."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from arena.config import Settings

REPO = Path(__file__).resolve().parents[2]
COMPOSE = REPO / "docker-compose.yml"
PINS = ("ARENA_POSTGRES_IMAGE", "ARENA_REDIS_IMAGE", "ARENA_PYTHON_IMAGE")
# Only through a setting with no default (`:?`): scripts/pin_images.py fills it.
PINNED = re.compile(r"\$\{(" + "|".join(PINS) + r"):\?[^}]*\}")


@pytest.fixture(scope="module")
def services() -> dict:
    return yaml.safe_load(COMPOSE.read_text())["services"]


def texts(value) -> list[str]:
    if isinstance(value, dict):
        return [t for item in value.values() for t in texts(item)]
    if isinstance(value, list):
        return [t for item in value for t in texts(item)]
    return [str(value)]


def test_no_secret_is_in_an_environment_or_command_line(services):
    plain = Settings.secret_env_names() - {"ARENA_DATABASE_URL", "ARENA_BROKER_URL"}
    for name, service in services.items():
        environment = service.get("environment") or {}
        assert not plain & set(environment), name
        assert "POSTGRES_PASSWORD" not in environment, name
        for url in ("ARENA_DATABASE_URL", "ARENA_BROKER_URL"):
            # A URL, never a password in it (user:password@host).
            assert not re.search(r"//[^/@]*:[^/@]*@", environment.get(url, "")), (name, url)
        words = " ".join(texts(service.get("command", "")) + texts(service.get("healthcheck", "")))
        assert not re.search(r"\$\{?(POSTGRES_PASSWORD|ARENA_\w*(TOKEN|SEED|PASSWORD))", words)
        assert "--seed" not in words and "--requirepass" not in words, name


def test_each_secret_file_is_declared_where_it_is_read(services):
    declared = yaml.safe_load(COMPOSE.read_text())["secrets"]
    for name, service in services.items():
        mounted = set(service.get("secrets") or [])
        assert mounted <= set(declared), name
        for key, value in (service.get("environment") or {}).items():
            if key.endswith("_FILE"):
                assert value.removeprefix("/run/secrets/") in mounted, (name, key)
    reads = {name: set(service.get("secrets") or []) for name, service in services.items()}
    # The seed only where the hidden suite is built; the admin token only in the API.
    assert {n for n, s in reads.items() if "hidden_seed" in s} == {"suites"}
    assert {n for n, s in reads.items() if "admin_token" in s} == {"api"}


def test_the_api_listens_on_loopback_without_group_0(services):
    api = services["api"]
    assert all(
        str(port).startswith("${ARENA_PUBLISH_ADDRESS:-127.0.0.1}:") for port in api["ports"]
    )
    for service in services.values():
        assert "0" not in [str(group) for group in service.get("group_add", [])]


def test_pulled_images_are_pinned_and_services_limited(services):
    for name, service in services.items():
        image = service.get("image", "")
        base = ((service.get("build") or {}).get("args") or {}).get("BASE_IMAGE", "")
        for reference in (image, base):
            if reference and not reference.startswith("driving-arena"):
                assert PINNED.fullmatch(reference), name
    for name in ("api", "worker"):
        assert {"cpus", "mem_limit", "memswap_limit", "pids_limit"} <= set(services[name]), name


def test_the_docker_socket_goes_only_to_a_worker_with_docker_sandboxes(services):
    for name, service in services.items():
        if any("docker.sock" in str(volume) for volume in service.get("volumes", [])):
            assert service["environment"]["ARENA_SANDBOX"] == "docker", name


@pytest.mark.skipif(shutil.which("docker-compose") is None, reason="docker-compose not installed")
def test_docker_compose_accepts_it(tmp_path):
    env = {**os.environ, "ARENA_SECRETS_DIR": str(tmp_path)}
    env |= {pin: f"local/{pin.lower()}@sha256:{'0' * 64}" for pin in PINS}
    done = subprocess.run(
        ["docker-compose", "-f", str(COMPOSE), "config", "--quiet"],
        env=env,
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    # Without the pins it refuses, naming how to make them.
    unpinned = {k: v for k, v in env.items() if k not in PINS}
    done = subprocess.run(
        ["docker-compose", "-f", str(COMPOSE), "config", "--quiet"],
        env=unpinned,
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert done.returncode != 0 and "pin_images.py" in done.stderr
