"""Where a corpus scene comes from, read from the file itself (CommonRoad's ``source`` attribute,
its authors) and the licence file beside it, unless the organiser states it (``--label``,
``--licence``). Traffic from a simulator is never called naturalistic."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from arena.scenario import DataLabel

LICENCE_FILES = ("LICENSE.txt", "LICENSE", "LICENSE.md", "LICENCE.txt", "LICENCE", "LICENCE.md")
# Sources that are recordings of real traffic, by the words their CommonRoad files use.
NATURALISTIC_SOURCES = {
    "NGSIM": ("ngsim", "next generation simulation"),
    "highD": ("highd",),
    "inD": ("ind dataset", "ind-dataset"),
    "rounD": ("round dataset", "round-dataset"),
    "INTERACTION": ("interaction dataset",),
}
_SIMULATED = re.compile(r"simulat|sumo|carla|synthetic|generated", re.IGNORECASE)
_NOT_A_SIMULATOR = re.compile(r"next generation simulation", re.IGNORECASE)


@dataclass(frozen=True)
class Provenance:
    label: DataLabel  # naturalistic (real recorded traffic) or recorded (a simulator's)
    source: str  # short name: "NGSIM", or the file's own words
    statement: str  # the file's ``source`` attribute as written ("" when it has none)
    licence: str | None  # licence text of the data, None when none came with it


def licence_text(folder: Path) -> str | None:
    for name in LICENCE_FILES:
        if (folder / name).is_file():
            return (folder / name).read_text()
    return None


def classify(statement: str, csv: bool = False) -> tuple[DataLabel, str]:
    """(label, short source name) of a scene whose file says ``statement``. NGSIM CSV files are
    NGSIM by format; a statement naming no known recording is not called naturalistic."""
    if csv:
        return DataLabel.naturalistic, "NGSIM"
    lowered = statement.lower()
    simulated = bool(_SIMULATED.search(_NOT_A_SIMULATOR.sub("", statement)))
    for name, words in NATURALISTIC_SOURCES.items():
        if any(w in lowered for w in words) and not simulated:
            return DataLabel.naturalistic, name
    return DataLabel.recorded, statement.strip() or "unknown source"


def provenance(
    statement: str,
    folder: Path,
    csv: bool = False,
    label: DataLabel | None = None,
    licence: Path | None = None,
) -> Provenance:
    """The scene's provenance: from its file and folder, ``label`` and ``licence`` (a licence
    file) overriding them."""
    found_label, source = classify(statement, csv)
    text = licence.read_text() if licence is not None else licence_text(folder)
    return Provenance(label or found_label, source, statement, text)


def attribution(
    prov: Provenance,
    scene: str,
    file: str,
    vehicle_id: str,
    origin: tuple[float, float] = (0.0, 0.0),
) -> str:
    """Provenance and licence text shipped in every scenario folder cut from a corpus scene
    (``origin``: the file's coordinates of the scenario's 0, 0)."""
    kind = (
        "naturalistic driving data"
        if prov.label is DataLabel.naturalistic
        else "recorded traffic, not naturalistic"
    )
    lines = [
        f"# Source: {prov.source} ({kind})\n",
        f"Scene `{scene}` (file `{file}`); the mission vehicle replaces recorded vehicle "
        f"`{vehicle_id}`.\n",
    ]
    if origin != (0.0, 0.0):
        lines.append(
            f"- Coordinates: the file's, less ({origin[0]:.0f}, {origin[1]:.0f}) m (a local frame)."
        )
    if prov.statement:
        lines.append(f"- The file states its source as: {prov.statement}.")
    if prov.source == "NGSIM":
        lines.append("- Trajectories: NGSIM, US Department of Transportation (public domain).")
    if re.search(r"openstreetmap|\bosm\b", prov.statement, re.IGNORECASE):
        lines.append(
            "- Road geometry partly derived from OpenStreetMap: (c) OpenStreetMap contributors "
            "(ODbL)."
        )
    if prov.licence is not None:
        lines.append("- Licence of the scene files: below.")
        return "\n".join(lines) + "\n\n## Licence\n\n" + prov.licence
    lines.append(
        "- No licence file came with the scene: check the data owner's terms before "
        "redistributing it."
    )
    return "\n".join(lines) + "\n"
