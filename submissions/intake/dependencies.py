"""A submission's ``requirements.txt``: resolved, downloaded and built only in the resolver
sandbox, kept in a wheel store shared by every submission.

The host never runs pip on a team's lines. It parses them (options, URLs and local paths are
refused, every line keeps its number) and hands them to the intake runner's resolver modes
(``agent_runtime/resolve.py``): ``download`` in a sandbox whose only reachable address is the
package index (:mod:`submissions.intake.package_index`), then ``build`` with no network at all
for each source distribution, then ``wheels``, which unpacks each new wheel under the archive
rules. The service's runner does each in a sandbox (``evaluator/sandbox/resolver.py``); a
participant's own machine runs the same program as a plain child with a minimal environment.

**The wheel store** (``DATA/deps/wheels/<sha256>``) holds each wheel unpacked once, named by the
hash of its bytes. A submission's folder (``DATA/deps/<key>``, keyed by its requirements, the
sandbox's interpreter and the sources) is made of hard links into it: read-only, mounted at
``/deps``, and on disk once however many submissions share a wheel. Its manifest
(``.stack.json``) names each wheel, its hash and sizes, and which framework builds were chosen
(torch's ``+cpu`` where the sandbox has no GPU). :func:`collect_garbage` removes the folders no
kept submission uses, then the wheels no folder uses.

Caps (``docs/submissions.md``): ``max_wheel_bytes`` per wheel, ``max_deps_download_bytes`` for
the whole stack downloaded, ``max_deps_bytes`` and ``max_deps_files`` unpacked.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import platform
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement
from packaging.utils import canonicalize_name

from agent_runtime import intake as rules
from agent_runtime import resolve as resolver_rules
from arena.config import IntakeSettings, SandboxSettings
from arena.errors import IntakeError
from arena.files import file_sha256
from submissions.intake.archive import make_read_only, remove_tree
from submissions.intake.contents import REQUIREMENTS
from submissions.intake.package_index import PackageSources, package_sources
from submissions.intake.porting import explain_unresolved
from submissions.intake.runner import IntakeRunner, write_inputs

DEPS_CACHE = "deps"
WHEEL_STORE = "wheels"
MANIFEST = ".stack.json"
# Frameworks published as CPU and GPU builds: the CPU build is chosen (the sandbox has no GPU).
CPU_FRAMEWORKS = ("torch", "torchvision", "torchaudio")


@dataclass(frozen=True)
class InstalledRequirements:
    key: str  # content key: the normalised requirements, the sandbox target and the sources
    folder: Path


@dataclass(frozen=True)
class Stack:
    """An organiser stack (:mod:`submissions.intake.stacks`) a submission's requirements add to."""

    name: str
    requirements: tuple[str, ...]  # its own lines
    lock: tuple[str, ...]  # project==version of every wheel built
    wheelhouse: Path


@dataclass(frozen=True)
class StackWheel:
    """One wheel of a submission's stack, as the manifest records it."""

    name: str
    sha256: str
    bytes: int  # the wheel file
    unpacked_bytes: int


def parse_requirements(text: str) -> list[tuple[int, str]]:
    """``(line number, normalised requirement)`` of every requirement line, in the file's order;
    pip options, URLs and local paths are refused."""
    lines = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(" #", 1)[0].strip()
        if not line or line.startswith("#"):
            continue
        entry = f"{REQUIREMENTS}:{number}"
        if line.startswith("-"):
            raise IntakeError(entry, "requirements-option", f"pip options are not allowed: {line}")
        try:
            requirement = Requirement(line)
        except InvalidRequirement as error:
            raise IntakeError(entry, "requirements-syntax", f"{line!r}: {error}") from error
        if requirement.url:
            raise IntakeError(entry, "requirements-url", f"direct URLs are not allowed: {line}")
        lines.append((number, str(requirement)))
    return lines


def sandbox_target(sandbox: SandboxSettings) -> list[str]:
    """pip's options selecting wheels for the sandbox's CPython and glibc on this machine's
    architecture: every manylinux tag that glibc runs (pip does not widen a PEP 600 tag itself).
    Only where the resolver does not run on the sandbox's own interpreter (a participant's
    machine); in the sandbox pip resolves for the interpreter it runs on."""
    version = sandbox.agent_python_version
    abi = "cp" + version.replace(".", "")
    arch = platform.machine()
    major, minor = (int(part) for part in sandbox.agent_glibc_version.split("."))
    platforms = [f"manylinux_{major}_{m}_{arch}" for m in range(minor, 4, -1)]
    platforms += [f"{legacy}_{arch}" for legacy in ("manylinux2014", "manylinux2010", "manylinux1")]
    options = ["--python-version", version, "--implementation", "cp", "--abi", abi]
    for name in platforms:
        options += ["--platform", name]
    return options


def resolve_request(
    lines: list[tuple[int, str]],
    sources: PackageSources,
    sandbox: SandboxSettings,
    intake: IntakeSettings,
) -> dict:
    """What the resolver is asked (``resolve.json``); the runner adds where pip and the proxy
    are. Target options are for a runner that is not the sandbox's interpreter (``target``)."""
    return {
        "requirements": [[number, line] for number, line in lines],
        "index_urls": list(sources.index_urls),
        "find_links": list(sources.find_links),
        "cert": sources.cert,
        "file_hosts": list(sources.file_hosts),
        "target": sandbox_target(sandbox),
        "python_version": sandbox.agent_python_version,
        "gpu": False,
        "cpu_frameworks": list(CPU_FRAMEWORKS),
        "constraints": [],
        "max_wheel_bytes": intake.max_wheel_bytes,
        "max_download_bytes": intake.max_deps_download_bytes,
    }


def requirements_key(request: dict) -> str:
    keyed = {k: v for k, v in request.items() if k != "requirements"}
    keyed["lines"] = sorted(line for _, line in request["requirements"])
    return hashlib.sha256(json.dumps(keyed, sort_keys=True).encode()).hexdigest()[:32]


def deps_cache(data_dir: Path) -> Path:
    return data_dir / DEPS_CACHE


def wheel_store(data_dir: Path) -> Path:
    return deps_cache(data_dir) / WHEEL_STORE


def install_requirements(
    text: str,
    intake: IntakeSettings,
    sandbox: SandboxSettings,
    data_dir: Path,
    runner: IntakeRunner,
    stack: Stack | None = None,
) -> InstalledRequirements | None:
    """The folder holding the installed requirements (on the organiser ``stack``, if any), or
    None when there are none."""
    lines = parse_requirements(text)
    conflicts = []
    if stack is not None:
        # A line the stack's lock excludes is told with the rest of the file's errors: it is
        # left out of the resolution so that pip, which names one conflict a run, names the
        # others (a 2022 file pins numpy, click, cloudpickle... the stack holds other versions).
        conflicts = lock_conflicts(lines, stack)
        excluded = {number for number, _ in conflicts}
        lines = [(n, line) for n, line in lines if n not in excluded]
        # The stack's own lines (numbered 0: not the team's) and its lock as constraints; its
        # wheelhouse is read before the index.
        lines = [(0, line) for line in stack.requirements] + lines
    if not lines:
        return None
    request = resolve_request(lines, package_sources(intake), sandbox, intake)
    if stack is not None:
        request["constraints"] = list(stack.lock)
        request["find_links"] = [str(stack.wheelhouse), *request["find_links"]]
    key = requirements_key(request)
    cache = deps_cache(data_dir)
    target = cache / key
    if not conflicts and (target / MANIFEST).is_file():
        return InstalledRequirements(key, target)
    cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".deps-", dir=cache))
    try:
        try:
            wheels, report = resolve(request, intake, work, runner, text)
        except IntakeError as error:
            if not conflicts:
                raise
            raise with_lock_conflicts(error, conflicts) from error
        if conflicts:
            raise with_lock_conflicts(None, conflicts)
        stack = store_wheels(wheels, intake, data_dir, work, runner)
        assemble(stack, report, request, data_dir, work / "stack")
        with contextlib.suppress(OSError):
            # Another intake finished the same requirements first; theirs is as good as ours.
            (work / "stack").rename(target)
        if not (target / MANIFEST).is_file():
            raise IntakeError(REQUIREMENTS, "intake-crashed", "the requirements' folder is gone")
        target.chmod(0o555)
    finally:
        remove_tree(work)
    return InstalledRequirements(key, target)


def lock_conflicts(lines: list[tuple[int, str]], stack: Stack) -> list[tuple[int, str]]:
    """``(line number, message)`` of each team line whose version range excludes the version
    the stack's lock holds of that project."""
    locked = {}
    for pin in stack.lock:
        name, _, version = pin.partition("==")
        locked[canonicalize_name(name)] = version
    found = []
    for number, line in lines:
        requirement = Requirement(line)
        held = locked.get(canonicalize_name(requirement.name))
        if held is not None and not requirement.specifier.contains(held, prereleases=True):
            found.append(
                (
                    number,
                    f"line {number} `{line}`: the stack {stack.name} holds "
                    f"{requirement.name} {held} (its versions are fixed): remove the line or "
                    "its version",
                )
            )
    return found


def with_lock_conflicts(error: IntakeError | None, conflicts: list[tuple[int, str]]) -> IntakeError:
    """The rejection telling the lines the stack excludes, and ``error``, the resolution's own
    rejection of the other lines, if any."""
    told = "; ".join(message for _, message in conflicts)
    if error is None:
        entry = f"{REQUIREMENTS}:{conflicts[0][0]}" if len(conflicts) == 1 else REQUIREMENTS
        return IntakeError(entry, "requirements-conflict", told)
    return IntakeError(REQUIREMENTS, error.rule, f"{told}; {error.message}")


def resolve(
    request: dict, intake: IntakeSettings, work: Path, runner: IntakeRunner, text: str
) -> tuple[list[Path], dict]:
    """The wheels of the resolved requirements (sdists built into wheels), and the report."""
    inputs = work / "resolve-in"
    inputs.mkdir()
    (inputs / resolver_rules.REQUEST).write_text(json.dumps(request))
    downloaded = work / "resolve-out"
    report = runner("download", inputs, downloaded)
    if report.get("cap") == "max-wheel-bytes":
        raise wheel_cap_error(REQUIREMENTS, intake)
    if not report.get("ok"):
        raise explain_unresolved(report, text, request["python_version"])
    wheels = sorted((downloaded / resolver_rules.WHEELS_DIR).glob("*.whl"))
    if report.get("sdists"):
        build_in = work / "build-in"
        build_in.mkdir()
        (build_in / resolver_rules.REQUEST).write_text(json.dumps(request))
        for name in (
            resolver_rules.SDISTS_DIR,
            resolver_rules.BUILD_DEPS_DIR,
            resolver_rules.LEGACY_BUILD_ENV,
        ):
            if (downloaded / name).is_dir():
                (downloaded / name).rename(build_in / name)
        built = runner("build", build_in, work / "build-out")
        if not built.get("ok"):
            unbuilt = explain_unresolved(built, text, request["python_version"])
            # The sdist exists: its build failed (the compiler's words are in the message).
            raise IntakeError(unbuilt.entry, "sdist-build", unbuilt.message)
        wheels += sorted((work / "build-out" / resolver_rules.WHEELS_DIR).glob("*.whl"))
    for wheel in wheels:
        size = wheel.stat().st_size
        if size > intake.max_wheel_bytes:
            raise wheel_cap_error(f"{REQUIREMENTS}: {wheel.name}", intake)
    total = sum(w.stat().st_size for w in wheels)
    if total > intake.max_deps_download_bytes:
        raise download_cap_error(intake)
    return wheels, report


def wheel_cap_error(entry: str, intake: IntakeSettings) -> IntakeError:
    return IntakeError(
        entry,
        "max-wheel-bytes",
        f"a wheel is larger than {intake.max_wheel_bytes / 1024**2:g} MiB, the cap on one wheel "
        "(a framework's GPU build is: the sandbox has no GPU, pin its CPU build)",
    )


def download_cap_error(intake: IntakeSettings) -> IntakeError:
    return IntakeError(
        REQUIREMENTS,
        "max-deps-download",
        f"the requirements' wheels are larger than {intake.max_deps_download_bytes / 1024**2:g} "
        "MiB together",
    )


def store_wheels(
    wheels: list[Path], intake: IntakeSettings, data_dir: Path, work: Path, runner: IntakeRunner
) -> list[StackWheel]:
    """Each wheel unpacked into the store once, by the hash of its bytes (the ``wheels`` step,
    in the sandbox for the service, only for the wheels the store lacks)."""
    store = wheel_store(data_dir)
    store.mkdir(parents=True, exist_ok=True)
    hashes = {wheel: file_sha256(wheel) for wheel in wheels}
    sizes = {wheel: wheel.stat().st_size for wheel in wheels}
    missing = [wheel for wheel in wheels if not (store / hashes[wheel]).is_dir()]
    if missing:
        staged = work / "wheels-in" / "staged"
        staged.mkdir(parents=True)
        for wheel in missing:
            wheel.rename(staged / wheel.name)
        write_inputs(work / "wheels-in", intake, {rules.WHEELS_DIR: staged})
        runner("wheels", work / "wheels-in", work / "wheels-out")
        for wheel in missing:
            unpacked = work / "wheels-out" / rules.DEPS_DIR / wheel.name
            make_read_only(unpacked)
            unpacked.chmod(0o755)  # moved below: its ".." changes
            with contextlib.suppress(OSError):
                unpacked.rename(store / hashes[wheel])
            (store / hashes[wheel]).chmod(0o555)
            # The same wheel may be checked by two intakes at once; either copy serves.
            remove_tree(unpacked)
    return [
        StackWheel(wheel.name, hashes[wheel], sizes[wheel], tree_bytes(store / hashes[wheel]))
        for wheel in wheels
    ]


def tree_bytes(folder: Path) -> int:
    total = 0
    for path, _, files in os.walk(folder):
        for name in files:
            total += os.lstat(os.path.join(path, name)).st_size
    return total


def assemble(
    stack: list[StackWheel], report: dict, request: dict, data_dir: Path, folder: Path
) -> None:
    """The submission's folder: every wheel's files hard-linked from the store (the first wheel
    providing a path wins, as one ``pip install --target`` would), and its manifest."""
    store = wheel_store(data_dir)
    folder.mkdir()
    for wheel in stack:
        link_tree(store / wheel.sha256, folder)
    manifest = {
        "requirements": request["requirements"],
        "wheels": [asdict(wheel) for wheel in stack],
        "cpu_builds": report.get("cpu_builds", {}),
        "built_from_source": report.get("sdists", []),
    }
    (folder / MANIFEST).write_text(json.dumps(manifest, indent=1))
    make_read_only(folder)
    folder.chmod(0o755)  # renamed into place by the caller


def link_tree(source: Path, dest: Path) -> None:
    for item in source.iterdir():
        target = dest / item.name
        if item.is_dir() and not item.is_symlink():
            target.mkdir(exist_ok=True)
            link_tree(item, target)
        elif not target.exists():
            os.link(item, target)


def read_manifest(folder: Path) -> dict:
    return json.loads((folder / MANIFEST).read_text())


def installed_versions(deps_dir: Path | None) -> dict[str, str]:
    """``{project: version}`` of a submission's stack, from its wheels' names: what the agent
    imports (the sandbox puts the folder ahead of its own libraries)."""
    if deps_dir is None or not (deps_dir / MANIFEST).is_file():
        return {}
    versions = {}
    for wheel in read_manifest(deps_dir)["wheels"]:
        project, version = wheel["name"].split("-")[:2]
        versions[project.lower().replace("_", "-")] = version
    return versions


def exclusive_bytes(data_dir: Path, keys_by_owner: dict[str, set[str]]) -> dict[str, int]:
    """Per owner (a team), the unpacked bytes of the wheels only its folders use: what a shared
    wheel costs is charged to no one."""
    users: dict[str, set[str]] = {}
    sizes: dict[str, int] = {}
    cache = deps_cache(data_dir)
    for owner, keys in keys_by_owner.items():
        for key in keys:
            if not (cache / key / MANIFEST).is_file():
                continue
            for wheel in read_manifest(cache / key)["wheels"]:
                users.setdefault(wheel["sha256"], set()).add(owner)
                sizes[wheel["sha256"]] = wheel["unpacked_bytes"]
    charged = dict.fromkeys(keys_by_owner, 0)
    for sha, owners in users.items():
        if len(owners) == 1:
            charged[next(iter(owners))] += sizes[sha]
    return charged


def collect_garbage(
    data_dir: Path, keys_in_use: set[str], min_age_s: float = 0.0, released: set[str] = frozenset()
) -> int:
    """Delete the requirement folders whose key no kept submission uses, then the stored wheels
    no folder links; returns how many folders went. Folders being installed (``.deps-*``) and
    those younger than ``min_age_s`` (maybe installed for a validation not yet recorded) are
    kept, unless ``released``: named by a submission that will never run again."""
    cache = deps_cache(data_dir)
    if not cache.is_dir():
        return 0
    removed = 0
    cutoff = time.time() - min_age_s
    kept_wheels: set[str] = set()
    freed_wheels: set[str] = set()  # linked by a released folder removed now
    for folder in cache.iterdir():
        if folder.name.startswith(".") or folder.name == WHEEL_STORE:
            continue
        wheels: set[str] = set()
        with contextlib.suppress(OSError, ValueError, KeyError):
            wheels = {w["sha256"] for w in read_manifest(folder)["wheels"]}
        young = folder.stat().st_mtime > cutoff and folder.name not in released
        if folder.name in keys_in_use or young:
            kept_wheels |= wheels
            continue
        if folder.name in released:
            freed_wheels |= wheels
        remove_tree(folder)
        removed += 1
    store = wheel_store(data_dir)
    # An intake under way may be linking stored wheels no folder names yet.
    if store.is_dir() and not any(p.name.startswith(".deps-") for p in cache.iterdir()):
        for wheel in store.iterdir():
            old = wheel.stat().st_mtime <= cutoff or wheel.name in freed_wheels
            if wheel.name not in kept_wheels and old:
                remove_tree(wheel)
    return removed
