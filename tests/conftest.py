"""The two tiers of the suite. The fast tier, ``pytest -m "not integration"``, runs on SQLite and
an in-memory broker with no server, daemon or browser (minutes); ``integration`` adds
PostgreSQL and Redis (``tests/server/conftest.py``), the sandboxes, Chromium, real service
processes and every test marked slow. ``./scripts/test.sh`` (and CI) runs both."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import get_settings
from scenarios.suites import build_suite

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
