"""A submission's ``requirements.txt``, installed from wheels only into its own folder.

pip resolves on the host with ``--only-binary=:all:`` (an sdist would run its build code here) and
then installs offline from the downloaded wheels with ``--target``; installing a wheel runs no code.
Both steps resolve for the **sandbox's** interpreter, not the host's: its Python version and
glibc (``agent_python_version``, ``agent_glibc_version``), so the folder holds wheels the policy
can import there; a set pip cannot satisfy together is refused with pip's own words naming the
conflict. The sandbox puts this folder ahead of its own libraries (numpy included), so what the
submission pins is what its policy imports. Folders are shared by every submission with the same
requirements and target, keyed by their hash.
"""

from __future__ import annotations

import hashlib
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement

from arena.config import Settings
from arena.errors import IntakeError
from submissions.intake.archive import make_read_only
from submissions.intake.contents import REQUIREMENTS
from submissions.intake.porting import explain_missing_wheel

PIP_TIMEOUT_S = 600
COMPLETE_MARKER = ".complete"


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


def sandbox_target(settings: Settings) -> list[str]:
    """pip's options selecting wheels for the sandbox's CPython and glibc on this machine's
    architecture: every manylinux tag that glibc runs (pip does not widen a PEP 600 tag itself)."""
    version = settings.agent_python_version
    abi = "cp" + version.replace(".", "")
    arch = platform.machine()
    major, minor = (int(part) for part in settings.agent_glibc_version.split("."))
    platforms = [f"manylinux_{major}_{m}_{arch}" for m in range(minor, 4, -1)]
    platforms += [f"{legacy}_{arch}" for legacy in ("manylinux2014", "manylinux2010", "manylinux1")]
    options = ["--python-version", version, "--implementation", "cp", "--abi", abi]
    for name in platforms:
        options += ["--platform", name]
    return options


def requirements_key(requirements: list[str], target: list[str]) -> str:
    return hashlib.sha256("\n".join([*target, *requirements]).encode()).hexdigest()[:32]


def install_requirements(text: str, settings: Settings) -> Path | None:
    """The folder holding the installed requirements, or None when there are none."""
    requirements = parse_requirements(text)
    if not requirements:
        return None
    cache = settings.resolved_data_dir / "deps"
    sandbox = sandbox_target(settings)
    target = cache / requirements_key(requirements, sandbox)
    if (target / COMPLETE_MARKER).is_file():
        return target
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="deps-", dir=cache) as tmp:
        work = Path(tmp)
        listed = work / REQUIREMENTS
        listed.write_text("\n".join(requirements) + "\n")
        wheels = work / "wheels"
        try:
            download = ["download", "--only-binary=:all:", *sandbox, "--dest", str(wheels)]
            pip(
                [*download, "-r", str(listed)],
                "no-wheel",
                "could not be resolved to wheels for the sandbox's Python "
                f"{settings.agent_python_version} (source distributions are not accepted)",
            )
        except IntakeError as error:
            raise explain_missing_wheel(error, text, settings.agent_python_version) from error
        installed = work / "deps"
        pip(
            [
                "install",
                "--no-index",
                "--only-binary=:all:",
                "--no-compile",
                *sandbox,
                "--find-links",
                str(wheels),
                "--target",
                str(installed),
                "-r",
                str(listed),
            ],
            "install-failed",
            "could not be installed from the downloaded wheels",
        )
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
            if not (target / COMPLETE_MARKER).is_file():
                raise
        else:
            target.chmod(0o555)
    return target


def pip(arguments: list[str], rule: str, failure: str) -> None:
    command = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q", *arguments]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=PIP_TIMEOUT_S)
    except subprocess.TimeoutExpired as error:
        raise IntakeError(REQUIREMENTS, rule, f"{failure}: pip timed out") from error
    if done.returncode != 0:
        detail = pip_error_summary(done.stderr or done.stdout)
        raise IntakeError(REQUIREMENTS, rule, f"{failure}: {detail}")


def pip_error_summary(output: str) -> str:
    """pip's own ERROR lines, without its warnings, notices and prefixes (what a participant
    needs: which requirement has no wheel); its last lines when it printed no ERROR line."""
    lines = [line.strip() for line in output.strip().splitlines() if line.strip()]
    errors = [line.removeprefix("ERROR: ") for line in lines if line.startswith("ERROR:")]
    if errors:
        return " / ".join(dict.fromkeys(errors))
    kept = [line for line in lines if not line.startswith(("WARNING:", "[notice]"))]
    return " / ".join((kept or lines)[-3:])
