"""Porting help for Driving SMARTS 2022 submissions: what in a zip shows it was written for SMARTS,
and what to do about it (``docs/submissions.md``, "Porting a SMARTS 2022 submission").

Notes do not reject a zip (a policy may keep such leftovers unused); a requirement without a
wheel does, with a message naming the line and the versions that do have one.
"""

from __future__ import annotations

import re
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement
from packaging.utils import canonicalize_name

from arena.errors import IntakeError
from submissions.intake.contents import POLICY, REQUIREMENTS

SMARTS_CONFIG = "config.yaml"
_NO_MATCH = re.compile(r"No matching distribution found for ([^\s/]+)")
_VERSIONS = re.compile(r"\(from versions: ([^)]*)\)")
_SHOWN_VERSIONS = 5  # the newest few versions with a wheel, named in the message


def porting_notes(root: Path, policy_defines: frozenset[str]) -> tuple[str, ...]:
    """Messages about SMARTS 2022 leftovers in the extracted submission ``root`` (empty when
    there are none); ``policy_defines``: the names policy.py defines at its top level."""
    notes = []
    if "submitted_wrappers" in policy_defines:
        notes.append(
            f"{POLICY} defines submitted_wrappers(): Driving Arena applies no gym wrappers. "
            "Call the wrappers' observation and action transforms inside Policy.act yourself, "
            "and set `observation_format: smarts2022` in agent.yaml to receive SMARTS-style "
            "observations (docs/smarts-compat.md)."
        )
    if (root / SMARTS_CONFIG).is_file():
        notes.append(
            f"{SMARTS_CONFIG} is not read by Driving Arena (it is only a file your policy may "
            "open). Interface options (action space, waypoints, rasters, observation format) go "
            "in agent.yaml (docs/submissions.md)."
        )
    return tuple(notes)


def explain_missing_wheel(error: IntakeError, requirements_text: str) -> IntakeError:
    """``error`` (pip found no wheel) restated: which line, which versions have a wheel, and
    what to do. The original error when pip's message names no distribution."""
    match = _NO_MATCH.search(error.message)
    if match is None:
        return error
    wanted = match.group(1)
    versions = _VERSIONS.search(error.message)
    available = [v.strip() for v in versions.group(1).split(",")] if versions else []
    available = [v for v in available if v and v != "none"]
    line = _line_naming(requirements_text, wanted)
    where = f"{REQUIREMENTS}:{line}" if line else REQUIREMENTS
    subject = wanted if line else f"{wanted} (a dependency of a listed requirement)"
    listed = "it" if line else "the requirement that pulls it in"
    if available:
        choice = f"pin a version that has one ({', '.join(available[-_SHOWN_VERSIONS:])})"
    else:
        choice = "replace it with a package that ships wheels"
    return IntakeError(
        where,
        "no-wheel",
        f"{subject} has no wheel for CPython 3.11 on Linux x86-64, and only wheels are installed "
        f"(no build code runs on our machines). {choice[0].upper()}{choice[1:]}, or remove "
        f"{listed} if the agent does not import it here: SMARTS 2022 requirement files list "
        "simulator packages (Panda3D, smarts) that a Driving Arena agent does not need.",
    )


def _line_naming(text: str, wanted: str) -> int | None:
    """The number of the requirements line naming the project of ``wanted`` (e.g. ``a==1``)."""
    try:
        project = canonicalize_name(Requirement(wanted).name)
    except InvalidRequirement:
        project = canonicalize_name(re.split(r"[=<>!~\[; ]", wanted, maxsplit=1)[0])
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(" #", 1)[0].strip()
        if not line or line.startswith(("#", "-")):
            continue
        try:
            if canonicalize_name(Requirement(line).name) == project:
                return number
        except InvalidRequirement:
            continue
    return None
