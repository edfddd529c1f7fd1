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
from arena.neutralise.log_view import visible
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
_SHOWN_VERSIONS = 5  # versions suggested for one line


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
    report: dict, requirements_text: str, python_version: str = "3.11"
) -> IntakeError:
    """A failed resolution (the resolver's report) told in one round: every line that no
    version satisfies, in the team's own line numbers, with versions to pin that resolve with
    the file's other lines; a dependency no index has; pip's explanation of a conflict, kept
    and neutralised, each requested project followed by its line. No path of ours is shown."""
    lines = _requirement_lines(requirements_text)
    told = []
    numbered = []
    for error in report.get("errors") or []:
        if not isinstance(error, dict):
            continue
        project = _bounded_text(error.get("project"))[:_MAX_NAME]
        number = error.get("line") if isinstance(error.get("line"), int) else None
        suggestions = [_bounded_text(v)[:_MAX_NAME] for v in error.get("suggestions") or []]
        where_python = f"the sandbox's CPython {python_version} on Linux {platform.machine()}"
        if number is not None:
            numbered.append(number)
            shown = _bounded_text(lines.get(number, project))[:_MAX_NAME]
            if error.get("available") == "none":
                fix = (
                    "the package index has no distribution of it at all: remove it, or use a "
                    "package that has one"
                )
            elif suggestions:
                fix = (
                    f"pin one of {', '.join(suggestions[:_SHOWN_VERSIONS])} (each resolves "
                    "with your other lines)"
                )
            else:
                fix = "no version of it resolves with your other lines; change or remove it"
            told.append(
                f"line {number} `{shown}`: no version of {project} on the package index for "
                f"{where_python} matches; {fix}"
            )
        else:
            available = _bounded_text(error.get("available"))[:_MAX_LIST]
            told.append(
                f"{project} (a dependency of a listed requirement) has no distribution on the "
                f"package index for {where_python} (versions there: {available}); pin the "
                "requirement that pulls it in to a version that does not need it"
            )
    conflict = [_neutral(line, lines) for line in report.get("conflict") or []][:_MAX_LINES]
    if conflict:
        told.append("pip: " + " / ".join(conflict))
    tail = [_neutral(line, lines) for line in report.get("tail") or []][:_MAX_LINES]
    if not told and tail:
        told.append("pip: " + " / ".join(tail))
    if not told:
        told.append("pip could not resolve them and said nothing we can show")
    if any(canonicalize_name(p) in _SIMULATOR_PROJECTS for p in _projects_of(report)):
        told.append(
            "SMARTS 2022 requirement files list simulator packages (Panda3D, smarts) that a "
            "Driving Arena agent does not need: remove them"
        )
    entry = (
        f"{REQUIREMENTS}:{numbered[0]}" if len(numbered) == 1 and len(told) == 1 else REQUIREMENTS
    )
    rule = "requirements-conflict" if conflict and not numbered else "no-distribution"
    return IntakeError(entry, rule, "; ".join(told))


# Projects of a SMARTS 2022 requirements file that no Driving Arena agent needs.
_SIMULATOR_PROJECTS = frozenset({"panda3d", "panda3d-gltf", "panda3d-simplepbr", "smarts"})
_MAX_NAME = 200
_MAX_LIST = 500
_MAX_LINES = 40
# An absolute path in pip's words is one of ours (the sandbox's folders, a temporary file).
_PATH = re.compile(r"(?<![\w.:/])/(?:[\w.+-]+/)*[\w.+-]*")
_REQUESTED = re.compile(r"The user requested \(?(?:constraint )?([A-Za-z0-9._-]+)")


def _requirement_lines(text: str) -> dict[int, str]:
    numbered = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(" #", 1)[0].strip()
        if line and not line.startswith(("#", "-")):
            numbered[number] = line
    return numbered


def _projects_of(report: dict) -> list[str]:
    return [
        e["project"]
        for e in report.get("errors") or []
        if isinstance(e, dict) and isinstance(e.get("project"), str)
    ]


def _neutral(line, numbered: dict[int, str]) -> str:
    """One line of pip's output as shown: bounded, control characters spelled out, our paths
    hidden, a requested project followed by the line of the team's file naming it."""
    text = visible(_bounded_text(line)[:_MAX_LIST])
    text = _PATH.sub("<path>", text)
    requested = _REQUESTED.search(text)
    if requested:
        wanted = canonicalize_name(requested.group(1))
        for number, entry in numbered.items():
            with contextlib.suppress(InvalidRequirement):
                if canonicalize_name(Requirement(entry).name) == wanted:
                    return f"{text} ({REQUIREMENTS}:{number})"
    return text
