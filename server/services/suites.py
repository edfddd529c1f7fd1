"""Scenario suites as the service sees them: a folder with ``manifest.json`` and one sub-folder per
scenario (written by ``arena scenarios build``)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from pydantic import BaseModel, ConfigDict, ValidationError

from arena.config import Settings
from server.services.errors import NotFound


class ManifestEntry(BaseModel):
    # Tolerant of fields added by the scenario builder; these are the ones the service uses.
    model_config = ConfigDict(frozen=True, extra="ignore")

    id: str
    family: str
    variant: str = ""
    volume: str | None = None
    agents: int = 1
    reactive: bool = True
    hash: str = ""


class Manifest(BaseModel):
    model_config = ConfigDict(frozen=True, extra="ignore")

    suite: str
    scenarios: tuple[ManifestEntry, ...]


class Suite(BaseModel):
    model_config = ConfigDict(frozen=True)

    root: Path
    manifest: Manifest
    manifest_sha256: str

    def scenario_dir(self, scenario_id: str) -> Path:
        return self.root / scenario_id

    def family_of(self) -> dict[str, str]:
        return {entry.id: entry.family for entry in self.manifest.scenarios}


def load_suite(root: Path) -> Suite:
    path = root / "manifest.json"
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise NotFound(f"no scenario suite at {root} (missing manifest.json)") from None
    try:
        manifest = Manifest.model_validate_json(raw)
    except ValidationError as exc:
        raise NotFound(f"{path} is not a valid suite manifest: {exc}") from exc
    return Suite(root=root, manifest=manifest, manifest_sha256=hashlib.sha256(raw).hexdigest())


def evaluation_suite_dir(settings: Settings) -> Path:
    """The hidden suite every submission is evaluated on."""
    return settings.hidden_suite_dir or settings.resolved_data_dir / "suites" / "hidden"


def public_suite_dir(settings: Settings) -> Path:
    """The public set: configured, else the one shipped in the repository."""
    return settings.public_suite_dir or Path(__file__).resolve().parents[2] / "scenarios" / "public"
