"""The two tiers of the suite. The fast tier, ``pytest -m "not integration"``, runs on SQLite and
an in-memory broker with no server, daemon or browser (minutes); ``integration`` adds
PostgreSQL and Redis (``tests/server/conftest.py``), the sandboxes, Chromium, real service
processes and every test marked slow. ``./scripts/test.sh`` (and CI) runs both."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import pytest

from arena.config import get_settings
from scenarios.suites import build_suite
from tests.planner_episodes import PlannerDigests, planner_digests_once

# Markers that mean a test needs more than this process, or takes long: such a test is
# integration whatever else it is.
INTEGRATION_MARKERS = ("slow", "docker", "bwrap", "browser")
# Fixtures that make a test using one integration: the session fixtures that build a whole suite
# (tens of seconds of map building and simulation), and Chromium (whether or not its module says
# `browser`).
INTEGRATION_FIXTURES = frozenset({"hidden_dev", "public_fresh", "hidden_corpus", "browser"})


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        marked = any(item.get_closest_marker(name) for name in INTEGRATION_MARKERS)
        if marked or INTEGRATION_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.integration)


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory) -> Path:
    """Maps and recordings of the suites a session builds."""
    return tmp_path_factory.mktemp("scenario-cache")


@pytest.fixture(scope="session")
def hidden_dev(tmp_path_factory, cache_dir) -> Path:
    """The hidden suite built with the development seed, once per test process."""
    out = tmp_path_factory.mktemp("hidden") / "suite"
    build_suite("hidden", get_settings().suites.development_seed, out, cache_dir)
    return out


@pytest.fixture(scope="session")
def planner_episode(tmp_path_factory) -> Callable[[str], PlannerDigests]:
    """The planner's episode digests of a public scenario, run once per test session: the tests of
    its actions and of its observations share it, from whichever xdist process (the processes of
    one session share the parent of their temporary folders, a new one each session)."""
    base = tmp_path_factory.getbasetemp()
    shared = (base.parent if "PYTEST_XDIST_WORKER" in os.environ else base) / "planner-episodes"
    return lambda scenario_id: planner_digests_once(scenario_id, shared)
