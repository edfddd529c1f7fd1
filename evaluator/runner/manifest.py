"""Reading a scenario suite folder: ``manifest.json`` plus one subfolder per scenario id."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from evaluator.errors import ArenaError

MANIFEST_FILE = "manifest.json"


class SuiteError(ArenaError):
    """The scenario folder or the scenario selection is unusable."""


@dataclass(frozen=True)
class SuiteScenario:
    id: str
    family: str


@dataclass(frozen=True)
class Manifest:
    suite: str
    hash: str  # sha256 of manifest.json
    scenarios: tuple[SuiteScenario, ...]

    def select(self, ids: Sequence[str] | None) -> Manifest:
        """The scenarios named in ``ids`` (manifest order), all when None."""
        if not ids:
            return self
        known = {scenario.id for scenario in self.scenarios}
        unknown = sorted(set(ids) - known)
        if unknown:
            raise SuiteError(f"no scenario {', '.join(unknown)} in suite {self.suite!r}")
        chosen = tuple(s for s in self.scenarios if s.id in set(ids))
        return Manifest(self.suite, self.hash, chosen)

    @property
    def family_of(self) -> dict[str, str]:
        return {scenario.id: scenario.family for scenario in self.scenarios}


def load_manifest(suite_dir: Path) -> Manifest:
    path = Path(suite_dir) / MANIFEST_FILE
    try:
        raw = path.read_bytes()
        data = json.loads(raw)
        scenarios = tuple(
            SuiteScenario(id=str(item["id"]), family=str(item["family"]))
            for item in data["scenarios"]
        )
        suite = str(data["suite"])
    except FileNotFoundError:
        raise SuiteError(f"{suite_dir} is not a scenario suite: no {MANIFEST_FILE}") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise SuiteError(f"{path}: malformed manifest ({exc!r})") from exc
    missing = [s.id for s in scenarios if not (Path(suite_dir) / s.id).is_dir()]
    if missing:
        raise SuiteError(f"{suite_dir}: scenario folders missing for {', '.join(missing)}")
    return Manifest(suite=suite, hash=hashlib.sha256(raw).hexdigest(), scenarios=scenarios)


def resolve_suite(suite: str | Path) -> Path:
    """``public`` is the repository's public set; anything else is a suite folder."""
    if str(suite) == "public":
        try:
            from scenarios.suites import public_suite_dir
        except ImportError:
            from arena.config import get_settings

            configured = get_settings().public_suite_dir
            if configured is None:
                raise SuiteError(
                    "no public suite here: build one with `arena scenarios build --suite public "
                    "--out DIR` and pass --suite DIR"
                ) from None
            return configured
        return Path(public_suite_dir())
    return Path(suite)
