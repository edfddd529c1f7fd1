"""The public suite as the API lists it."""

from __future__ import annotations

from arena.config import Settings
from arena.errors import SuiteError
from arena.suite import ManifestEntry, load_suite, public_suite_dir
from server.services.errors import NotFound


def public_scenarios(settings: Settings) -> tuple[ManifestEntry, ...]:
    try:
        return load_suite(public_suite_dir(settings)).scenarios
    except SuiteError as exc:
        raise NotFound(f"no public suite: {exc}") from exc
