"""Suites built once per test session (maps and recordings cached in a session folder; the
hidden development build and the cache are shared by every package: tests/conftest.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from scenarios.suites import PUBLIC_SEED, build_suite


@pytest.fixture(scope="session")
def scenes_dir() -> Path:
    """The shipped naturalistic scenes (scenarios/data/naturalistic/commonroad-ngsim)."""
    from arena.config import get_settings
    from scenarios.recorded.naturalistic import shipped_scenes_dir

    folder = shipped_scenes_dir(get_settings().suites.naturalistic_dir)
    # The scenes ship in the repository: missing ones are a broken checkout or setting, never a
    # reason to skip.
    if not (folder / "PROVENANCE.md").exists():
        pytest.fail(f"naturalistic scenes not found at {folder} (check ARENA_NATURALISTIC_DIR)")
    return folder


@pytest.fixture(scope="session")
def public_fresh(tmp_path_factory, cache_dir) -> Path:
    out = tmp_path_factory.mktemp("public") / "suite"
    build_suite("public", PUBLIC_SEED, out, cache_dir)
    return out


def manifest(folder: Path) -> dict:
    return json.loads((folder / "manifest.json").read_text())
