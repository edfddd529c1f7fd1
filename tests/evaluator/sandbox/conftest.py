"""Fixtures for sandbox tests: real sandboxes of each backend, unique labels, leftover checks."""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import pytest

from arena.config import SandboxKind, Settings
from evaluator.sandbox import start
from evaluator.sandbox.backend import SANDBOX_LABEL
from evaluator.sandbox.backend_registry import backend_for
from evaluator.sandbox.subprocess_sandbox import labelled_pids
from tests.evaluator.sandbox.agents import agent, observation
from tests.settings import sandbox_args, with_fields

ISOLATING = [
    pytest.param(SandboxKind.bubblewrap, marks=pytest.mark.bwrap, id="bubblewrap"),
    pytest.param(SandboxKind.docker, marks=pytest.mark.docker, id="docker"),
]
ALL_KINDS = [*ISOLATING, pytest.param(SandboxKind.process, id="process")]


@pytest.fixture(scope="session")
def settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    return with_fields(
        Settings(),
        storage={"data_dir": tmp_path_factory.mktemp("data")},
        sandbox={"init_timeout_s": 20.0, "step_timeout_s": 1.0},
    )


def usable(kind: SandboxKind, settings: Settings) -> SandboxKind:
    reason = backend_for(kind).unavailable_reason(settings.sandbox)
    if reason is not None:
        # CI installs and starts every sandbox (scripts/setup-sandbox.sh): there a missing one is
        # a failure, not a reason to skip the hostile-submission tests.
        if os.environ.get("CI"):
            pytest.fail(f"{kind.value} sandbox unavailable in CI: {reason}")
        pytest.skip(f"{kind.value} sandbox unavailable here: {reason}")
    return kind


@pytest.fixture(params=ISOLATING)
def kind(request: pytest.FixtureRequest, settings: Settings) -> SandboxKind:
    return usable(request.param, settings)


@pytest.fixture(params=ALL_KINDS)
def any_kind(request: pytest.FixtureRequest, settings: Settings) -> SandboxKind:
    return usable(request.param, settings)


@pytest.fixture
def labels() -> dict[str, str]:
    return {"driving-arena.test": uuid.uuid4().hex}


@pytest.fixture(scope="session")
def good_agent(tmp_path_factory: pytest.TempPathFactory, settings: Settings):
    return agent(tmp_path_factory.mktemp("good"), settings)


def leftovers(kind: SandboxKind, labels: dict[str, str]) -> list:
    wanted = {SANDBOX_LABEL: "1", **labels}
    if kind is SandboxKind.docker:
        from evaluator.sandbox.docker_backend import docker_client

        selector = [f"{key}={value}" for key, value in wanted.items()]
        return docker_client().containers.list(all=True, filters={"label": selector})
    return labelled_pids(wanted)


def assert_clean_and_healthy(kind: SandboxKind, labels, settings: Settings, good_agent) -> None:
    """Nothing of the last agent is left, and the next agent on this worker runs fine."""
    assert leftovers(kind, labels) == []
    with start(
        good_agent,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        handle.reset()
        assert handle.act(observation()) == {"Agent_0": [1.0, 0.0]}
    assert leftovers(kind, labels) == []


@pytest.fixture
def tmp(tmp_path: Path) -> Path:
    """pytest's folders are private to root: the sandboxes must cope with that."""
    return tmp_path
