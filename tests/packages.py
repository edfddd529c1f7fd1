"""Our packages as the layers contract names them (``pyproject.toml``), so that no test keeps a
list of its own that a new package would slip past."""

from __future__ import annotations

import tomllib
from pathlib import Path

_PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"

ALL = tuple(tomllib.loads(_PYPROJECT.read_text())["tool"]["importlinter"]["root_packages"])
# The sandbox's side of the wall: it imports nothing of ours and shares none of our types.
SANDBOX_RUNTIME = "agent_runtime"
HOST = tuple(name for name in ALL if name != SANDBOX_RUNTIME)

__all__ = ["ALL", "HOST", "SANDBOX_RUNTIME"]
