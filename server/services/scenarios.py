"""The public suite as the API lists it."""

from __future__ import annotations

from arena.config import SuiteSettings
from arena.errors import SuiteError
from arena.suite import ManifestEntry, load_suite, public_suite_dir
from server.services.errors import NotFound


def public_scenarios(suites: SuiteSettings) -> tuple[ManifestEntry, ...]:
    try:
        return load_suite(public_suite_dir(suites)).scenarios
    except SuiteError as exc:
        raise NotFound(f"no public suite: {exc}") from exc
