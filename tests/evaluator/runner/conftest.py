"""Fixtures for runner tests that need the simulator, the public suite and example agents."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import SandboxKind

# Independent of Docker; the docker-marked test covers the production sandbox.
TEST_SANDBOX = SandboxKind.process


@pytest.fixture(scope="session")
def public_suite() -> Path:
    from arena.suite import SHIPPED_PUBLIC_DIR

    return SHIPPED_PUBLIC_DIR


def write_policy(folder: Path, body: str, action_space: str = "LaneWithContinuousSpeed") -> Path:
    """A submission folder with ``policy.py`` = ``body`` and the given action space."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "policy.py").write_text(body)
    (folder / "agent.yaml").write_text(f"action_space: {action_space}\n")
    return folder
