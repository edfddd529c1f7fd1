"""A submission's ``requirements.txt``: wheels only, downloaded with a cap, unpacked under one.

pip resolves and downloads on the host, where the package index is reachable (as the host's pip
configuration says, plus ``ARENA_PIP_OPTIONS``), with ``--only-binary=:all:`` (an sdist would
run its build code) and the download folder's size watched: past ``ARENA_MAX_DEPS_DOWNLOAD_BYTES``
pip is stopped. Unpacking the wheels (a wheel is a zip; installing one runs no code) is the
intake runner's ``wheels`` step, in the sandbox for the service, under the archive rules and the
caps on total unpacked bytes and files. Folders are shared by every submission with the same
requirements, keyed by their content; the service deletes those no submission uses any more.

pip resolves for the **sandbox's** interpreter, not the host's: its Python version and glibc
(``agent_python_version``, ``agent_glibc_version``), so the folder holds wheels the policy can
import there; a set pip cannot satisfy together is refused with pip's own words naming the
conflict. The sandbox puts this folder ahead of its own libraries (numpy included), so what the
submission pins is what its policy imports.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement

from agent_runtime import intake as rules
from arena.config import IntakeSettings, SandboxSettings
from arena.errors import IntakeError
from submissions.intake.archive import make_read_only, remove_tree
from submissions.intake.contents import REQUIREMENTS
from submissions.intake.porting import explain_missing_wheel
from submissions.intake.runner import IntakeRunner, write_inputs

PIP_TIMEOUT_S = 600
POLL_S = 0.2
COMPLETE_MARKER = ".complete"
DEPS_CACHE = "deps"


@dataclass(frozen=True)
class InstalledRequirements:
    key: str  # content key: the normalised requirements and the sandbox target
    folder: Path


def parse_requirements(text: str) -> list[str]:
    """Normalised requirement lines; pip options, URLs and local paths are refused."""
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
        lines.append(str(requirement))
    return sorted(lines)


def sandbox_target(sandbox: SandboxSettings) -> list[str]:
    """pip's options selecting wheels for the sandbox's CPython and glibc on this machine's
    architecture: every manylinux tag that glibc runs (pip does not widen a PEP 600 tag itself)."""
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


def requirements_key(requirements: list[str], target: list[str]) -> str:
    return hashlib.sha256("\n".join([*target, *requirements]).encode()).hexdigest()[:32]


def deps_cache(data_dir: Path) -> Path:
    return data_dir / DEPS_CACHE


def install_requirements(
    text: str,
    intake: IntakeSettings,
    sandbox: SandboxSettings,
    data_dir: Path,
    runner: IntakeRunner,
) -> InstalledRequirements | None:
    """The folder holding the installed requirements, or None when there are none."""
    requirements = parse_requirements(text)
    if not requirements:
        return None
    target_options = sandbox_target(sandbox)
    key = requirements_key(requirements, target_options)
    cache = deps_cache(data_dir)
    target = cache / key
    if (target / COMPLETE_MARKER).is_file():
        return InstalledRequirements(key, target)
    cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".deps-", dir=cache))
    try:
        listed = work / REQUIREMENTS
        listed.write_text("\n".join(requirements) + "\n")
        wheels = work / "wheels"
        try:
            download_wheels(listed, wheels, intake, sandbox, target_options)
        except IntakeError as error:
            raise explain_missing_wheel(error, text, sandbox.agent_python_version) from error
        write_inputs(work / "in", intake, {rules.WHEELS_DIR: wheels})
        runner("wheels", work / "in", work / "out")
        installed = work / "out" / rules.DEPS_DIR
        (installed / COMPLETE_MARKER).write_text("\n".join(requirements) + "\n")
        make_read_only(installed)
        # Moving a folder to another parent rewrites its "..": it stays writable until then
        # (root does not care; an unprivileged intake, such as the API's in docker-compose.yml,
        # is refused otherwise).
        installed.chmod(0o755)
        try:
            installed.rename(target)
        except OSError:
            # Another intake finished the same requirements first; theirs is as good as ours.
            remove_tree(installed)
            if not (target / COMPLETE_MARKER).is_file():
                raise
        else:
            target.chmod(0o555)
    finally:
        remove_tree(work / "out")
        shutil.rmtree(work, ignore_errors=True)
    return InstalledRequirements(key, target)


def download_wheels(
    listed: Path, wheels: Path, intake: IntakeSettings, sandbox: SandboxSettings, target: list[str]
) -> None:
    """``pip download`` of the listed requirements' wheels (and their dependencies' wheels) for
    the sandbox's interpreter (``target``: :func:`sandbox_target`), stopped once the download
    folder holds more than the cap."""
    command = [
        sys.executable,
        "-m",
        "pip",
        "--disable-pip-version-check",
        "-q",
        "download",
        "--only-binary=:all:",
        *target,
        *intake.pip_options,
        "--dest",
        str(wheels),
        "-r",
        str(listed),
    ]
    cap = intake.max_deps_download_bytes
    failure = (
        "could not be resolved to wheels for the sandbox's Python "
        f"{sandbox.agent_python_version} (source distributions are not accepted)"
    )
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
        started = time.monotonic()
        try:
            while process.poll() is None:
                time.sleep(POLL_S)
                if folder_bytes(wheels) > cap:
                    raise IntakeError(
                        REQUIREMENTS,
                        "max-deps-download",
                        f"the requirements' wheels are larger than {cap / 1024**2:g} MiB",
                    )
                if time.monotonic() - started > PIP_TIMEOUT_S:
                    raise IntakeError(REQUIREMENTS, "no-wheel", f"{failure}: pip timed out")
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        if folder_bytes(wheels) > cap:
            raise IntakeError(
                REQUIREMENTS,
                "max-deps-download",
                f"the requirements' wheels are larger than {cap / 1024**2:g} MiB",
            )
        if process.returncode != 0:
            log.seek(0)
            output = log.read(256 * 1024).decode("utf-8", "replace")
            raise IntakeError(REQUIREMENTS, "no-wheel", f"{failure}: {pip_error_summary(output)}")


def folder_bytes(folder: Path) -> int:
    if not folder.is_dir():
        return 0
    total = 0
    for entry in os.scandir(folder):
        if entry.is_file(follow_symlinks=False):
            total += entry.stat(follow_symlinks=False).st_size
    return total


def pip_error_summary(output: str) -> str:
    """pip's own ERROR lines, without its warnings, notices and prefixes (what a participant
    needs: which requirement has no wheel); its last lines when it printed no ERROR line."""
    lines = [line.strip() for line in output.strip().splitlines() if line.strip()]
    errors = [line.removeprefix("ERROR: ") for line in lines if line.startswith("ERROR:")]
    if errors:
        return " / ".join(dict.fromkeys(errors))
    kept = [line for line in lines if not line.startswith(("WARNING:", "[notice]"))]
    return " / ".join((kept or lines)[-3:])


def collect_garbage(data_dir: Path, keys_in_use: set[str], min_age_s: float = 0.0) -> int:
    """Delete the requirement folders whose key no kept submission uses; returns how many.
    Folders being installed (``.deps-*``) and those younger than ``min_age_s`` (installed for
    a validation not yet recorded) are left alone."""
    cache = deps_cache(data_dir)
    if not cache.is_dir():
        return 0
    removed = 0
    cutoff = time.time() - min_age_s
    for folder in cache.iterdir():
        if folder.name.startswith(".") or folder.name in keys_in_use:
            continue
        if folder.stat().st_mtime > cutoff:
            continue
        remove_tree(folder)
        removed += 1
    return removed
