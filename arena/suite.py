"""A scenario suite on disk: ``manifest.json`` plus one folder per scenario id.

``scenarios`` writes suites, the evaluator runs them, the service stores which one a run used:
all through :class:`SuiteManifest` and :func:`load_suite`. Where the public and hidden suites live
is decided here, once.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError

from arena.config import SuiteSettings
from arena.errors import SuiteError
from arena.scenario import DataLabel, Family

MANIFEST_FILE = "manifest.json"
PUBLIC = "public"
HIDDEN = "hidden"
# The public set ships with the repository, built from the public seed.
SHIPPED_PUBLIC_DIR = Path(__file__).resolve().parents[1] / "scenarios" / "public"


class ManifestEntry(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    id: str
    family: Family
    variant: str = ""
    volume: str | None = None
    agents: int = 1
    reactive: bool = True
    hash: str = ""  # sha256 of the scenario folder (arena.scenario.content_hash)
    label: DataLabel = DataLabel.synthetic
    # The solvability rule: the expert completes the scenario, or this says why not.
    unsolvable_reason: str | None = None
    source: str | None = None  # naturalistic replays: the recording's origin, e.g. NGSIM


class SuiteManifest(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    suite: str
    netconvert: str | None = None  # the netconvert that built the maps (builds are byte-exact)
    scenarios: tuple[ManifestEntry, ...]
    # A build with --naturalistic-dir: the scene files its scenarios were cut from (name, file,
    # sha256, recording location, source, the origin of its local frame; their vehicles' poses
    # are beside the manifest in naturalistic-tracks.json), the files it skipped
    # (file, reason), how many recorded vehicles it rejected as missions, per reason, and the
    # drawn missions the log replay expert did not finish (file, vehicle, reason).
    naturalistic_scenes: tuple[dict[str, Any], ...] | None = None
    naturalistic_skipped: tuple[dict[str, str], ...] | None = None
    naturalistic_rejected: dict[str, int] | None = None
    naturalistic_unsolved: tuple[dict[str, str], ...] | None = None
    seed: int | None = None  # public suites only
    seed_fingerprint: str | None = None  # hidden suites: the seed itself is never written

    def to_json(self) -> str:
        """The manifest as the builds write it: optional fields only where they are set."""
        data = self.model_dump(
            mode="json",
            exclude={
                "naturalistic_scenes",
                "naturalistic_skipped",
                "naturalistic_rejected",
                "naturalistic_unsolved",
                "seed",
                "seed_fingerprint",
            },
        )
        for entry in data["scenarios"]:
            if entry["source"] is None:
                del entry["source"]
        if self.naturalistic_scenes is not None:
            data["naturalistic_scenes"] = list(self.naturalistic_scenes)
            data["naturalistic_skipped"] = list(self.naturalistic_skipped or ())
            data["naturalistic_rejected"] = dict(self.naturalistic_rejected or {})
            data["naturalistic_unsolved"] = list(self.naturalistic_unsolved or ())
        if self.seed is not None:
            data["seed"] = self.seed
        if self.seed_fingerprint is not None:
            data["seed_fingerprint"] = self.seed_fingerprint
        return json.dumps(data, indent=2) + "\n"


@dataclass(frozen=True)
class Suite:
    """A loaded suite (or a selection of its scenarios)."""

    root: Path
    manifest: SuiteManifest
    sha256: str  # of manifest.json: identifies the suite a result was computed on

    @property
    def name(self) -> str:
        return self.manifest.suite

    @property
    def scenarios(self) -> tuple[ManifestEntry, ...]:
        return self.manifest.scenarios

    def scenario_dir(self, scenario_id: str) -> Path:
        return self.root / scenario_id

    def family_of(self) -> dict[str, str]:
        return {entry.id: entry.family.value for entry in self.scenarios}

    def select(self, ids: Sequence[str] | None) -> Suite:
        """The scenarios named in ``ids`` (manifest order), all when None or empty."""
        if not ids:
            return self
        known = {entry.id for entry in self.scenarios}
        unknown = sorted(set(ids) - known)
        if unknown:
            raise SuiteError(f"no scenario {', '.join(unknown)} in suite {self.name!r}")
        chosen = tuple(entry for entry in self.scenarios if entry.id in set(ids))
        return replace(self, manifest=self.manifest.model_copy(update={"scenarios": chosen}))


def load_suite(root: Path) -> Suite:
    root = Path(root)
    path = root / MANIFEST_FILE
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise SuiteError(f"{root} is not a scenario suite: no {MANIFEST_FILE}") from None
    except OSError as exc:  # unreadable to this process (permissions): say so, never a crash
        raise SuiteError(f"{root}: cannot read {MANIFEST_FILE}: {exc.strerror}") from None
    try:
        manifest = SuiteManifest.model_validate_json(raw)
    except ValidationError as exc:
        raise SuiteError(f"{path}: malformed manifest: {exc}") from None
    missing = [entry.id for entry in manifest.scenarios if not (root / entry.id).is_dir()]
    if missing:
        raise SuiteError(f"{root}: scenario folders missing for {', '.join(missing)}")
    return Suite(root=root, manifest=manifest, sha256=hashlib.sha256(raw).hexdigest())


def write_manifest(root: Path, manifest: SuiteManifest) -> None:
    (Path(root) / MANIFEST_FILE).write_text(manifest.to_json())


def public_suite_dir(suites: SuiteSettings) -> Path:
    """The public set: configured, else the one shipped in the repository."""
    return suites.public_suite_dir or SHIPPED_PUBLIC_DIR


def hidden_suite_dir(suites: SuiteSettings, data_dir: Path) -> Path:
    """The hidden suite every submission is evaluated on: configured, else under the (resolved)
    data folder."""
    return suites.hidden_suite_dir or data_dir / "suites" / HIDDEN


def resolve_suite(suite: str | Path, suites: SuiteSettings, data_dir: Path) -> Path:
    """``public`` and ``hidden`` name the configured suites; anything else is a suite folder."""
    if str(suite) == PUBLIC:
        return public_suite_dir(suites)
    if str(suite) == HIDDEN:
        return hidden_suite_dir(suites, data_dir)
    return Path(suite)
