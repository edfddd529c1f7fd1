"""Organiser stacks: named, locked wheel sets a submission builds on (``stack: ds2022`` in
``agent.yaml``), its ``requirements.txt`` adding to them.

An organiser builds a stack once (``arena stacks build NAME``: resolved, downloaded and built in
the resolver sandbox like any team's requirements). It is kept under ``DATA/stacks/NAME``: its
wheels (an organiser wheelhouse, which the resolver reads as a folder, so a stack's wheels are
never fetched again), ``lock.txt`` (each project pinned to the version built) and
``stack.json``. A submission naming it is resolved with the lock as constraints and the stack's
own lines as requirements, so its folder holds the stack and what the team adds; every wheel is
stored (and on disk) once, whoever uses it. ``arena evaluate`` reads the same folder.
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
from pathlib import Path

from arena.config import IntakeSettings, SandboxSettings
from arena.errors import IntakeError
from submissions.intake.archive import remove_tree
from submissions.intake.contents import AGENT_YAML
from submissions.intake.dependencies import (
    Stack,
    deps_cache,
    parse_requirements,
    resolve,
    resolve_request,
    store_wheels,
)
from submissions.intake.package_index import package_sources
from submissions.intake.runner import IntakeRunner

STACKS_DIR = "stacks"
LOCK = "lock.txt"
STACK_MANIFEST = "stack.json"
STACK_NAME = re.compile(r"[a-z0-9][a-z0-9_.-]{0,63}")
# The stacks the service knows how to build, by name. ds2022: what the Driving SMARTS 2022
# agents whose code is public import (the `smarts` and gym 0.21 compatibility modules come with
# `observation_format: smarts2022`, not from a wheel). torch resolves to its CPU build.
BUILTIN_STACKS = {
    "ds2022": "torch\nnumpy==1.23.5\ngym==0.26.2\nd3rlpy==1.1.1\n",
}


def stacks_dir(data_dir: Path) -> Path:
    return data_dir / STACKS_DIR


def check_stack_name(name: object) -> str:
    if not isinstance(name, str) or not STACK_NAME.fullmatch(name):
        raise IntakeError(
            AGENT_YAML, "stack", "`stack:` names a stack: lower-case letters, digits, . _ -"
        )
    return name


def read_stack(data_dir: Path, name: str) -> Stack:
    """The built stack ``name``; an IntakeError naming the built ones when there is none."""
    folder = stacks_dir(data_dir) / check_stack_name(name)
    if not (folder / STACK_MANIFEST).is_file():
        listed = ", ".join(m["name"] for m in built_stacks(data_dir)) or "none"
        raise IntakeError(
            AGENT_YAML,
            "stack",
            f"no stack {name!r} is built here (built: {listed}; organisers build one with "
            "`arena stacks build NAME`)",
        )
    manifest = json.loads((folder / STACK_MANIFEST).read_text())
    return Stack(
        name=name,
        requirements=tuple(manifest["requirements"]),
        lock=tuple((folder / LOCK).read_text().split()),
        wheelhouse=folder / "wheels",
    )


def built_stacks(data_dir: Path) -> list[dict]:
    """Every built stack's manifest, by name."""
    return [
        json.loads((p / STACK_MANIFEST).read_text())
        for p in sorted(stacks_dir(data_dir).glob("*"))
        if (p / STACK_MANIFEST).is_file()
    ]


def build_stack(
    name: str,
    text: str,
    intake: IntakeSettings,
    sandbox: SandboxSettings,
    data_dir: Path,
    runner: IntakeRunner,
) -> dict:
    """Resolve ``text`` (requirement lines) into the stack ``name`` (replacing one of that
    name): its wheelhouse, lock and manifest, each wheel unpacked into the shared store."""
    check_stack_name(name)
    lines = parse_requirements(text)
    if not lines:
        raise IntakeError(name, "stack", "a stack needs at least one requirement")
    request = resolve_request(lines, package_sources(intake), sandbox, intake)
    deps_cache(data_dir).mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".deps-stack-", dir=deps_cache(data_dir)))
    try:
        wheels, report = resolve(request, intake, work, runner, text)
        house = work / "stack" / "wheels"
        house.mkdir(parents=True)
        for wheel in wheels:
            shutil.copyfile(wheel, house / wheel.name)
        stored = store_wheels(wheels, intake, data_dir, work, runner)
        lock = sorted(f"{w.name.split('-')[0]}=={w.name.split('-')[1]}" for w in stored)
        (work / "stack" / LOCK).write_text("\n".join(lock) + "\n")
        manifest = {
            "name": name,
            "requirements": [line for _, line in lines],
            "wheels": [{"name": w.name, "sha256": w.sha256, "bytes": w.bytes} for w in stored],
            "cpu_builds": report.get("cpu_builds", {}),
            "built_from_source": report.get("sdists", []),
        }
        (work / "stack" / STACK_MANIFEST).write_text(json.dumps(manifest, indent=1))
        target = stacks_dir(data_dir) / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.exists():
            remove_tree(target)
        (work / "stack").rename(target)
        for path in [target, *target.rglob("*")]:
            path.chmod(0o755 if path.is_dir() else 0o644)
    finally:
        remove_tree(work)
    return manifest
