"""Porting help for Driving SMARTS 2022 submissions: what in a zip shows it was written for SMARTS,
and what to do about it (``docs/submissions.md``, "Porting a SMARTS 2022 submission").

Notes do not reject a zip (a policy may keep such leftovers unused); a requirement without a
wheel does, with a message naming the line and the versions that do have one.
"""

from __future__ import annotations

import ast
import contextlib
import platform
import re
import zipfile
from dataclasses import dataclass, field

import yaml
from packaging.requirements import InvalidRequirement, Requirement
from packaging.utils import canonicalize_name

from arena.errors import IntakeError
from submissions.intake.archive import read_entry
from submissions.intake.contents import AGENT_YAML, POLICY, REQUIREMENTS, read_text

SMARTS_CONFIG = "config.yaml"
SMARTS_FORMAT = "smarts2022"
# numpy's aliases of Python types, removed in numpy 1.24 -> the Python type to use instead.
NUMPY_ALIASES = {
    "float": "float",
    "int": "int",
    "bool": "bool",
    "object": "object",
    "str": "str",
    "long": "int",
    "unicode": "str",
    "complex": "complex",
}
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
_MAX_SCANNED_FILES = 500
_MAX_SCANNED_BYTES = 1 << 20
_NO_MATCH = re.compile(r"No matching distribution found for ([^\s/]+)")
_VERSIONS = re.compile(r"\(from versions: ([^)]*)\)")
_SHOWN_VERSIONS = 5  # the newest few versions with a wheel, named in the message


def porting_notes(archive: zipfile.ZipFile) -> tuple[str, ...]:
    """Messages about SMARTS 2022 leftovers in the zip (empty when there are none): what the
    three published 2022 agents needed when ported (``docs/submissions.md``)."""
    scan = _scan(archive)
    smarts_format = _observation_format(archive) == SMARTS_FORMAT
    requirements = _required_projects(read_text(archive, REQUIREMENTS) or "")
    notes = []
    if scan.defines_wrappers and not smarts_format:
        notes.append(
            f"{POLICY} defines submitted_wrappers(): Driving Arena applies them (around an "
            "environment that gives SMARTS's observations, as the 2022 evaluation did) only with "
            "`observation_format: smarts2022` in agent.yaml (docs/smarts-compat.md)."
        )
    smarts_modules = sorted(m for m in scan.imports if m.split(".")[0] == "smarts")
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
    if "gym" in {m.split(".")[0] for m in scan.imports} and "gym" not in requirements:
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
    aliases = sorted(scan.numpy_aliases)
    if aliases and not _pins_old_numpy(read_text(archive, REQUIREMENTS) or ""):
        names = ", ".join(f"np.{a}" for a in aliases)
        notes.append(
            f"uses {names}, removed in numpy 1.24 (the sandbox's numpy is newer): use the Python "
            f"types ({', '.join(NUMPY_ALIASES[a] for a in aliases)}), or pin an older numpy in "
            "requirements.txt (e.g. numpy==1.23.5), which the policy then imports."
        )
    if read_text(archive, SMARTS_CONFIG) is not None:
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


@dataclass
class _Scan:
    imports: set[str] = field(default_factory=set)  # modules imported (`from m import x`: m)
    numpy_aliases: set[str] = field(default_factory=set)  # np.float and the like used
    defines_wrappers: bool = False  # policy.py defines submitted_wrappers()


def _scan(archive: zipfile.ZipFile) -> _Scan:
    """Imports and removed numpy aliases of the zip's Python files (syntax trees only: nothing
    of the participant's runs here)."""
    scan = _Scan()
    sources = [i for i in archive.infolist() if i.filename.endswith(".py") and not i.is_dir()]
    for info in sources[:_MAX_SCANNED_FILES]:
        try:
            tree = ast.parse(read_entry(archive, info, _MAX_SCANNED_BYTES))
        except (SyntaxError, ValueError, RecursionError, MemoryError):
            continue  # check_policy names what is wrong with policy.py; others are not ours
        if info.filename == POLICY:
            scan.defines_wrappers = any(
                isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
                and node.name == "submitted_wrappers"
                for node in tree.body
            )
        numpy_names = {"numpy"}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    scan.imports.add(alias.name)
                    if alias.name == "numpy":
                        numpy_names.add(alias.asname or "numpy")
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                scan.imports.add(node.module)
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and node.attr in NUMPY_ALIASES
                and isinstance(node.value, ast.Name)
                and node.value.id in numpy_names
            ):
                scan.numpy_aliases.add(node.attr)
    scan.imports = {m for m in scan.imports if _is_module_like(m)}
    return scan


def _is_module_like(name: str) -> bool:
    return all(part.isidentifier() for part in name.split("."))


def _observation_format(archive: zipfile.ZipFile) -> str | None:
    try:
        options = yaml.safe_load(read_text(archive, AGENT_YAML) or "") or {}
    except yaml.YAMLError:
        return None
    return options.get("observation_format") if isinstance(options, dict) else None


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
