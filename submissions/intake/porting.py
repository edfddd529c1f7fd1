"""Porting help for Driving SMARTS 2022 submissions: what in a zip shows it was written for SMARTS,
and what to do about it (``docs/submissions.md``, "Porting a SMARTS 2022 submission").

Notes do not reject a zip (a policy may keep such leftovers unused); a requirement without a
wheel does, with a message naming the line and the versions that do have one.
"""

from __future__ import annotations

import contextlib
import platform
import re
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement
from packaging.utils import canonicalize_name

from agent_runtime import intake as rules
from arena.errors import IntakeError
from submissions.intake.contents import POLICY, REQUIREMENTS
from submissions.intake.runner import read_sandbox_json

SMARTS_CONFIG = rules.SMARTS_CONFIG
SMARTS_FORMAT = "smarts2022"
# The modules (and names imported from them) of agent_runtime/compat/smarts.
SMARTS_COMPAT_MODULES = frozenset(
    {
        "smarts",
        "smarts.core",
        "smarts.core.agent",
        "smarts.core.agent_interface",
        "smarts.core.controllers",
        "smarts.core.coordinates",
        "smarts.core.events",
        "smarts.core.observations",
        "smarts.core.plan",
        "smarts.core.road_map",
        "smarts.core.sensors",
        "smarts.core.utils",
        "smarts.core.utils.math",
        "smarts.core.waypoints",
        "smarts.env",
        "smarts.env.wrappers",
        "smarts.env.wrappers.format_action",
        "smarts.env.wrappers.format_obs",
        "smarts.env.wrappers.frame_stack",
        "smarts.zoo",
        "smarts.zoo.agent_spec",
    }
)
_MAX_SCAN_REPORT_BYTES = 256 * 1024
_NO_MATCH = re.compile(r"No matching distribution found for ([^\s/]+)")
_VERSIONS = re.compile(r"\(from versions: ([^)]*)\)")
_SHOWN_VERSIONS = 5  # the newest few versions with a wheel, named in the message


def porting_notes(scan: dict | None) -> tuple[str, ...]:
    """Messages about SMARTS 2022 leftovers in a submission (empty when there are none): what the
    three published 2022 agents needed when ported (``docs/submissions.md``). ``scan``: what its
    Python files import and use and what its configuration files say, found in the sandbox by
    :func:`agent_runtime.intake.scan_sources` and ``porting_facts`` (None: not scanned)."""
    scan = scan or {}
    imports = _names(scan, "imports")
    numpy_aliases = _names(scan, "numpy_aliases") & set(rules.NUMPY_ALIASES)
    smarts_format = scan.get("observation_format") == SMARTS_FORMAT
    requirements_text = _bounded_text(scan.get("requirements"))
    requirements = _required_projects(requirements_text)
    notes = []
    if scan.get("defines_wrappers") is True and not smarts_format:
        notes.append(
            f"{POLICY} defines submitted_wrappers(): Driving Arena applies them (around an "
            "environment that gives SMARTS's observations, as the 2022 evaluation did) only with "
            "`observation_format: smarts2022` in agent.yaml (docs/smarts-compat.md)."
        )
    smarts_modules = sorted(m for m in imports if m.split(".")[0] == "smarts")
    if smarts_modules and "smarts" not in requirements:
        if not smarts_format:
            notes.append(
                f"imports {', '.join(smarts_modules)}: the sandbox provides a `smarts` "
                "compatibility package (observation types, Waypoint, ActionSpaceType, math "
                "utilities, FormatObs/FormatAction) only with `observation_format: smarts2022` "
                "in agent.yaml (docs/smarts-compat.md)."
            )
        else:
            missing = [m for m in smarts_modules if m not in SMARTS_COMPAT_MODULES]
            if missing:
                notes.append(
                    f"imports {', '.join(missing)}: not part of the sandbox's `smarts` "
                    "compatibility package (docs/smarts-compat.md lists what is); the import "
                    "fails unless you copy what you use into your submission."
                )
    if "gym" in {m.split(".")[0] for m in imports} and "gym" not in requirements:
        if smarts_format:
            notes.append(
                "imports gym: the sandbox provides gym 0.21's Env, wrappers and spaces (enough "
                "for the competition kit's wrappers); anything else of gym is not there."
            )
        else:
            notes.append(
                "imports gym, which the sandbox does not have: with `observation_format: "
                "smarts2022` it provides gym 0.21's Env, wrappers and spaces; or use gymnasium "
                "and list it in requirements.txt."
            )
    aliases = sorted(numpy_aliases)
    if aliases and not _pins_old_numpy(requirements_text):
        names = ", ".join(f"np.{a}" for a in aliases)
        notes.append(
            f"uses {names}, removed in numpy 1.24 (the sandbox's numpy is newer): use the Python "
            f"types ({', '.join(rules.NUMPY_ALIASES[a] for a in aliases)}), or pin an older "
            "numpy in requirements.txt (e.g. numpy==1.23.5), which the policy then imports."
        )
    if scan.get("smarts_config") is True:
        notes.append(
            f"{SMARTS_CONFIG} is not read by Driving Arena (it is only a file your policy may "
            "open). Interface options (action space, waypoints, rasters, observation format) go "
            "in agent.yaml (docs/submissions.md)."
        )
    return tuple(notes)


def with_porting_notes(error: IntakeError, notes: tuple[str, ...]) -> IntakeError:
    """``error`` with the porting notes appended: a rejected SMARTS 2022 port gets them too."""
    if not notes:
        return error
    listed = " ".join(f"Porting note: {note}" for note in notes)
    return IntakeError(error.entry, error.rule, f"{error.message} {listed}")


def read_scan(output: Path) -> dict | None:
    """The sandbox's scan of the Python files and configuration (:data:`agent_runtime.intake.
    PORTING` in the intake's output folder, written where the participant's bytes were handled:
    bounded)."""
    return read_sandbox_json(output / rules.PORTING, _MAX_SCAN_REPORT_BYTES)


def _names(scan: dict, key: str) -> set[str]:
    values = scan.get(key)
    return {v for v in values if isinstance(v, str)} if isinstance(values, list) else set()


def _bounded_text(value) -> str:
    return value if isinstance(value, str) and len(value) <= rules.MAX_CONFIG_BYTES else ""


def _required_projects(text: str) -> set[str]:
    projects = set()
    for raw in text.splitlines():
        line = raw.split(" #", 1)[0].strip()
        if not line or line.startswith(("#", "-")):
            continue
        with contextlib.suppress(InvalidRequirement):
            projects.add(canonicalize_name(Requirement(line).name))
    return projects


def _pins_old_numpy(text: str) -> bool:
    """Whether requirements.txt allows only a numpy that still has the removed aliases."""
    for raw in text.splitlines():
        line = raw.split(" #", 1)[0].strip()
        try:
            requirement = Requirement(line)
        except InvalidRequirement:
            continue
        if canonicalize_name(requirement.name) == "numpy" and requirement.specifier:
            allows = requirement.specifier.contains
            old = any(allows(f"1.{minor}.{patch}") for minor in range(17, 24) for patch in range(7))
            new = any(allows(v) for v in ("1.24.0", "1.24.4", "1.26.4", "2.0.0", "2.2.6", "2.4.0"))
            return old and not new
    return False


def explain_missing_wheel(
    error: IntakeError, requirements_text: str, python_version: str = "3.11"
) -> IntakeError:
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
        f"{subject} has no wheel for the sandbox's CPython {python_version} on Linux "
        f"{platform.machine()}, and only wheels are installed "
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
