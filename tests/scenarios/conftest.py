"""Suites built once per test session (maps and recordings cached in a session folder)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from arena.config import get_settings
from scenarios.suites import PUBLIC_SEED, build_suite


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("scenario-cache")


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
def hidden_dev(tmp_path_factory, cache_dir) -> Path:
    out = tmp_path_factory.mktemp("hidden") / "suite"
    build_suite("hidden", get_settings().suites.development_seed, out, cache_dir)
    return out


@pytest.fixture(scope="session")
def public_fresh(tmp_path_factory, cache_dir) -> Path:
    out = tmp_path_factory.mktemp("public") / "suite"
    build_suite("public", PUBLIC_SEED, out, cache_dir)
    return out


def manifest(folder: Path) -> dict:
    return json.loads((folder / "manifest.json").read_text())
