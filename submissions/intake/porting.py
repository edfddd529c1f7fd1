"""Porting help for Driving SMARTS 2022 submissions: what in a zip shows it was written for SMARTS,
and what to do about it (``docs/submissions.md``, "Porting a SMARTS 2022 submission").

Notes do not reject a zip (a policy may keep such leftovers unused); a requirement without a
wheel does, with a message naming the line and the versions that do have one, and so does a
``smarts2022`` submission taking a module or name the sandbox's ``smarts`` / ``gym`` packages lack
(:func:`missing_compat_names`), naming each with its file and line.
"""

from __future__ import annotations

import ast
import contextlib
import platform
import re
from functools import lru_cache
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement
from packaging.utils import canonicalize_name

import agent_runtime
from agent_runtime import intake as rules
from arena.errors import IntakeError
from arena.neutralise.log_view import visible
from submissions.intake.contents import POLICY, REQUIREMENTS
from submissions.intake.runner import read_sandbox_json

SMARTS_CONFIG = rules.SMARTS_CONFIG
SMARTS_FORMAT = "smarts2022"
# The packages the sandbox adds for observation_format: smarts2022 (agent_runtime/compat).
COMPAT_DIR = Path(agent_runtime.__file__).parent / "compat"
_SHOWN_NAMES = 20  # missing names listed in one rejection
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
            guarded = _missing_compat_names(scan, guarded=True)
            if guarded:
                notes.append(
                    f"imports, inside a try that catches ImportError, {_listed(guarded)}: not "
                    "part of the sandbox's compatibility packages (docs/smarts-compat.md lists "
                    "what is); that code path takes its except branch."
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


def missing_compat_names(scan: dict | None) -> IntakeError | None:
    """The rejection of a ``smarts2022`` submission that takes, outside a ``try`` catching
    ImportError, a module or name the sandbox's ``smarts`` or ``gym`` package lacks (each
    ``from smarts... import NAME``, ``import smarts...`` and attribute read through such a
    module, as :func:`agent_runtime.intake.compat_names` found them): it would fail at that
    import or call when it runs. None when there is none, or when the submission ships or
    requires its own package."""
    missing = _missing_compat_names(scan or {}, guarded=False)
    if not missing:
        return None
    first = missing[0].split(" ", 1)[0]
    return IntakeError(
        first,
        "smarts-compat-name",
        "uses what the sandbox's `smarts` / `gym` compatibility packages do not have, so the "
        f"agent would fail there when it runs: {_listed(missing)}. Copy what you use into your "
        "submission (docs/smarts-compat.md lists what the packages have; private names are "
        "not provided).",
    )


def _missing_compat_names(scan: dict, *, guarded: bool) -> list[str]:
    """``file:line path`` of each use the compat packages lack, in the scan's order, once each;
    only uses inside (``guarded``) or outside a try catching ImportError."""
    if scan.get("observation_format") != SMARTS_FORMAT:
        return []
    own = _names(scan, "ships_packages") | _required_projects(
        _bounded_text(scan.get("requirements"))
    )
    uses = scan.get("compat_uses")
    missing: list[str] = []
    for use in uses if isinstance(uses, list) else []:
        if not (isinstance(use, list) and len(use) == 4):
            continue
        where, line, path, inside = use
        if not (isinstance(where, str) and isinstance(line, int) and isinstance(path, str)):
            continue
        if inside is not guarded or path.split(".")[0] in own or _compat_has(path):
            continue
        shown = f"{visible(where[:_MAX_NAME])}:{line} {visible(path[:_MAX_NAME])}"
        if shown not in missing:
            missing.append(shown)
    return missing


def _listed(missing: list[str]) -> str:
    more = len(missing) - _SHOWN_NAMES
    return "; ".join(missing[:_SHOWN_NAMES]) + (f"; and {more} more" if more > 0 else "")


def _compat_has(path: str) -> bool:
    """Whether ``smarts.a.b.NAME...`` resolves in the compat packages: the longest module prefix,
    then one name of it (a top-level name or a submodule); what follows a name is not checked."""
    modules = compat_modules()
    parts = path.split(".")
    for end in range(len(parts), 0, -1):
        module = ".".join(parts[:end])
        if module in modules:
            break
    else:
        return False
    if end == len(parts):
        return True
    name = parts[end]
    return name in modules[module] or (name.startswith("__") and name.endswith("__"))


@lru_cache(maxsize=1)
def compat_modules() -> dict[str, frozenset[str]]:
    """Each module of the compat packages (dotted) -> the names it has: what it defines or
    imports at its top level, and its submodules. Read from the sources (nothing imported)."""
    modules: dict[str, set[str]] = {}
    stars: dict[str, list[str]] = {}  # module -> the modules it star-imports
    for source in sorted(COMPAT_DIR.rglob("*.py")):
        parts = source.relative_to(COMPAT_DIR).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if not parts:
            continue  # the compat folder's own __init__: not a package agents import
        module = ".".join(parts)
        tree = ast.parse(source.read_text())
        modules.setdefault(module, set()).update(rules.top_level_names(tree))
        stars[module] = [
            node.module
            for node in tree.body
            if isinstance(node, ast.ImportFrom) and node.module and node.names[0].name == "*"
        ]
        if len(parts) > 1:
            modules.setdefault(".".join(parts[:-1]), set()).add(parts[-1])
    for module, sources in stars.items():
        for source in sources:
            public = {n for n in modules.get(source, ()) if not n.startswith("_")}
            modules[module] |= public - {"*"}
    return {module: frozenset(names - {"*"}) for module, names in modules.items()}


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


def explain_unresolved(
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
            place = f"line {number} `{shown}`" if number else f"the stack's `{project}`"
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
                f"{place}: no version of {project} on the package index for "
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
