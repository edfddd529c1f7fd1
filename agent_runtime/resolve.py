"""Resolving a submission's ``requirements.txt`` inside the resolver sandbox.

Standard library only, and no import of this project: ``evaluator/sandbox/resolver.py`` runs this
file in a sandbox of its own (``python3 resolve.py MODE INPUT OUTPUT``) with no secret and no host
variable in its environment, as uid 65534, bounded in time, memory and bytes. pip is the
evaluator's own (a pure-Python package mounted read-only), run on the sandbox's interpreter, so
what it resolves is what the agent imports. Its configuration is what ``INPUT/resolve.json`` says
and nothing else (``PIP_CONFIG_FILE=/dev/null``: no host file, constraint or variable reaches it).

Two modes, two sandboxes:

- ``download``: the only reachable address is the package index, through a relay to the host's
  index proxy (``proxy``: a unix socket; the sandbox's network namespace has only loopback) or a
  folder mounted read-only. pip resolves and downloads wheels, and sdists where a project has no
  wheel (their metadata hooks run here, never on the host), then the build requirements of each
  sdist. A failed resolution is told in one round: every line that no version satisfies, pip's
  conflict explanation, and versions to pin that resolve with the file's other lines.
- ``build``: no network at all; each sdist is built into a wheel from the downloaded build
  requirements only. The wheels are then checked like any other (``intake.py wheels``).

The verdict is ``OUTPUT/report.json``: ``{"ok": true, ...}`` or ``{"ok": false, "errors": [...],
"conflict": [...]}``, each error ``{"line", "project", "message", "suggestions"}``.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tarfile
import threading
import tomllib
import zipfile
from pathlib import Path

REQUEST = "resolve.json"
REPORT = "report.json"
WHEELS_DIR = "wheels"
BUILD_DEPS_DIR = "build-deps"
SDISTS_DIR = "sdists"
SDIST_SUFFIXES = (".tar.gz", ".zip", ".tar.bz2", ".tgz")
# setuptools' own default when an sdist says nothing (PEP 517 legacy path).
DEFAULT_BUILD_REQUIRES = ["setuptools>=40.8.0", "wheel"]
MAX_PIP_OUTPUT = 256 * 1024
MAX_SUGGESTIONS = 3
# How many versions of one line are tried against the others before giving up on suggesting.
MAX_TRIED_VERSIONS = 4
RELAY_CHUNK = 64 * 1024
FILE_TOO_LARGE = "[Errno 27] File too large"
MAX_TAIL_LINES = 24
# Lines of each failed build's own words when several failed (their names come first).
MIN_TAIL_LINES_EACH = 4
LEGACY_BUILD_ENV = "legacy-build-env"
# What legacy setup.py files import without declaring it (d3rlpy 1.1.1: Cython and numpy, which
# pip's isolated build environment lacks); the file's own numpy pin applies (the built extension
# must match the numpy the agent imports).
LEGACY_BUILD_REQUIRES = ("setuptools", "wheel", "Cython<3", "numpy")
_LEGACY_FAILURE = re.compile(r"metadata-generation-failed|ModuleNotFoundError: No module named")
_WORKING_ON = ("Collecting ", "Downloading ", "Processing ", "Building wheel for ")
_BOILERPLATE = ("note:", "hint:", "╰─> See above", "[notice]")
# pip's own lines around a failed build's output.
_PIP_FRAMING = (
    "error: subprocess-exited-with-error",
    "×",
    "│",
    "╰─>",
    "ERROR: Failed",
    "Failed to",
    "Building wheel for",
)
# "error" as a word (a compiler's "error:"; not "-Werror=") or an exception's name.
_ERROR_WORD = re.compile(r"(?<![\w-])[Ee]rror\b|[a-z]Error\b")
_VERSIONS_LINE = re.compile(r"^Available versions: (.*)$", re.MULTILINE)
_NO_MATCH = re.compile(r"No matching distribution found for (\S+)")
_FROM_VERSIONS = re.compile(r"\(from versions: ([^)]*)\)")


def pump(source: socket.socket, sink: socket.socket) -> None:
    """Copy ``source`` to ``sink`` until it ends, then end ``sink``'s writing half (the relay
    here and the host's index proxy both move bytes this way)."""
    try:
        while chunk := source.recv(RELAY_CHUNK):
            sink.sendall(chunk)
    except OSError:
        pass
    finally:
        with contextlib.suppress(OSError):
            sink.shutdown(socket.SHUT_WR)


def start_relay(proxy_socket: str) -> int:
    """A loopback port forwarding each connection to the host's index proxy (a unix socket): the
    sandbox's network namespace has no other way out. Returns the port."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)

    def serve() -> None:
        while True:
            client, _ = listener.accept()
            upstream = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                upstream.connect(proxy_socket)
            except OSError:
                client.close()
                upstream.close()
                continue
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=pump, args=(a, b), daemon=True).start()

    threading.Thread(target=serve, name="index-relay", daemon=True).start()
    return listener.getsockname()[1]


class Pip:
    """pip as this request configures it, and nothing else."""

    def __init__(self, request: dict, output: Path, proxy_port: int | None) -> None:
        self.request = request
        scratch = output / "tmp"
        scratch.mkdir(parents=True, exist_ok=True)
        self.env = {
            "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
            "HOME": str(scratch),
            # On disk, where the host counts the bytes (a wheel may not fit a small /tmp).
            "TMPDIR": str(scratch),
            "LANG": "C.UTF-8",
            "PIP_CONFIG_FILE": os.devnull,
            "PIP_NO_INPUT": "1",
            "PIP_DISABLE_PIP_VERSION_CHECK": "1",
            # No cache: every byte in the output folder is one the download cap counts once.
            "PIP_NO_CACHE_DIR": "1",
            "PYTHONDONTWRITEBYTECODE": "1",
        }
        if request.get("pip_path"):
            self.env["PYTHONPATH"] = request["pip_path"]
        # The proxy and the index's certificate as pip's variables, not options: the pip that
        # installs an sdist's build requirements (build isolation) inherits the environment, not
        # the options, and had no way out (kiwisolver's `cppy` was "on no index").
        if proxy_port is not None:
            self.env["PIP_PROXY"] = f"http://127.0.0.1:{proxy_port}"
        if request.get("cert"):
            self.env["PIP_CERT"] = request["cert"]
        self.isolation: list[str] = []

    def use_build_env(self, folder: Path) -> None:
        """Build sdists against ``folder``'s packages, not in pip's isolated environment."""
        paths = [self.request.get("pip_path"), str(folder)]
        self.env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
        self.isolation = ["--no-build-isolation"]

    def index_options(self) -> list[str]:
        urls = list(self.request.get("index_urls") or [])
        options = ["--index-url", urls[0]] if urls else ["--no-index"]
        for url in urls[1:]:
            options += ["--extra-index-url", url]
        for link in self.request.get("find_links") or []:
            options += ["--find-links", link]
        return options

    def target_options(self, binary_only: bool = False) -> list[str]:
        """Another interpreter's wheels (a participant's own machine): wheels only, as pip
        requires; in the sandbox the interpreter is the agent's, and sdists are allowed."""
        target = list(self.request.get("target") or [])
        if target or binary_only:
            return [*target, "--only-binary=:all:"]
        return ["--prefer-binary"]

    def run(self, command: str, *arguments: str) -> tuple[int, str]:
        process = subprocess.run(
            [sys.executable, "-m", "pip", "--no-color", command, *arguments],
            env=self.env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            check=False,
        )
        return process.returncode, process.stdout[-MAX_PIP_OUTPUT:].decode("utf-8", "replace")

    def versions(self, project: str) -> list[str]:
        """Every version of ``project`` the index has for this interpreter, newest first."""
        target = list(self.request.get("target") or [])
        code, output = self.run(
            "index", "versions", "--pre", project, *self.index_options(), *target
        )
        found = _VERSIONS_LINE.search(output)
        if code != 0 or found is None:
            return []
        return [v.strip() for v in found.group(1).split(",") if v.strip()]


def packaging():
    """pip's own copy of ``packaging`` (pip is on the path; this file imports nothing else)."""
    from pip._vendor.packaging import requirements, utils, version

    return requirements, utils, version


def requirement_of(text: str):
    requirements, _, _ = packaging()
    try:
        return requirements.Requirement(text)
    except requirements.InvalidRequirement:
        return None


def project_of(text: str) -> str:
    _, utils, _ = packaging()
    parsed = requirement_of(text)
    name = parsed.name if parsed else re.split(r"[=<>!~\[;@ ]", text, maxsplit=1)[0]
    return utils.canonicalize_name(name)


def allowed(text: str, versions: list[str]) -> list[str]:
    """The ``versions`` (newest first) the requirement line accepts."""
    _, _, version = packaging()
    parsed = requirement_of(text)
    if parsed is None:
        return []
    kept = []
    for candidate in versions:
        try:
            if parsed.specifier.contains(version.Version(candidate), prereleases=True):
                kept.append(candidate)
        except version.InvalidVersion:
            continue
    return kept


def cpu_builds(pip: Pip, lines: list[str], projects: set[str]) -> dict[str, str]:
    """For each framework of ``projects`` (torch...) in a sandbox without a GPU: the newest
    ``+cpu`` build its line accepts (any, when only a dependency pulls it in), pinned exactly,
    so pip does not pick a CUDA build (gigabytes of GPU libraries the sandbox cannot use)."""
    if pip.request.get("gpu"):
        return {}
    named = {project_of(line): line for line in reversed(lines)}
    chosen = {}
    for project in sorted(projects & set(pip.request.get("cpu_frameworks") or [])):
        found = allowed(named.get(project, project), pip.versions(project))
        cpu = [v for v in found if v.endswith("+cpu")]
        if cpu:
            chosen[project] = cpu[0]
    return chosen


def gpu_builds_downloaded(wheels: Path) -> set[str]:
    """The projects downloaded in a build that is not a CPU one (a framework among them was
    pulled in by a dependency)."""
    found = set()
    for wheel in wheels.glob("*.whl"):
        project, version = wheel.name.split("-")[:2]
        if not version.endswith("+cpu"):
            found.add(project_of(project))
    return found


def write_lines(path: Path, lines: list[str]) -> Path:
    path.write_text("".join(f"{line}\n" for line in lines))
    return path


def download(pip: Pip, lines: list[str], constraints: list[str], dest: Path, scratch: Path) -> str:
    """pip download of ``lines`` into ``dest``; '' on success, else pip's output. The lines are
    arguments, not a requirements file: pip expands ``${VAR}`` in files, never in arguments."""
    constraint_file = write_lines(scratch / "constraints.txt", constraints)
    code, output = pip.run(
        "download",
        "--progress-bar",
        "off",
        "--dest",
        str(dest),
        *pip.isolation,
        *pip.target_options(),
        *pip.index_options(),
        "-c",
        str(constraint_file),
        "--",
        *lines,
    )
    return "" if code == 0 else output


def legacy_build_env(pip: Pip, lines: list[str], constraints: list[str], output: Path) -> bool:
    """Install :data:`LEGACY_BUILD_REQUIRES` (as the file's pins and the constraints allow) for
    building sdists without isolation; whether that worked."""
    pins = [line for line in lines if "==" in line]
    constraint_file = write_lines(output / "tmp" / "constraints-build.txt", [*constraints, *pins])
    code, _ = pip.run(
        "install",
        "--target",
        str(output / LEGACY_BUILD_ENV),
        *pip.target_options(binary_only=True),
        *pip.index_options(),
        "-c",
        str(constraint_file),
        "--",
        *LEGACY_BUILD_REQUIRES,
    )
    if code == 0:
        pip.use_build_env(output / LEGACY_BUILD_ENV)
    return code == 0


def resolves(pip: Pip, lines: list[str], constraints: list[str], scratch: Path) -> bool:
    """Whether ``lines`` resolve together (pip's dry run: nothing installed)."""
    constraint_file = write_lines(scratch / "constraints-check.txt", constraints)
    code, _ = pip.run(
        "install",
        "--dry-run",
        "--ignore-installed",
        # Not into the interpreter's own packages: a Debian Python refuses those (PEP 668).
        "--target",
        str(scratch / "dry-run"),
        "--quiet",
        *pip.target_options(),
        *pip.index_options(),
        "-c",
        str(constraint_file),
        "--",
        *lines,
    )
    return code == 0


def conflict_block(output: str) -> list[str]:
    """pip's explanation of a conflict: what cannot be installed together and why."""
    lines = output.splitlines()
    kept = [line.removeprefix("ERROR: ") for line in lines if line.startswith("ERROR: Cannot ")]
    try:
        start = next(i for i, line in enumerate(lines) if line.startswith("The conflict is"))
    except StopIteration:
        return kept
    kept.append(lines[start])
    for line in lines[start + 1 :]:
        if not line.strip():
            break
        kept.append(line.strip())
    return kept


def unresolvable_lines(
    pip: Pip, numbered: list[list], constraints: list[str], scratch: Path
) -> list[dict]:
    """Every line that no available version satisfies, each with versions to pin instead that
    resolve with the file's other lines (newest first)."""
    errors = []
    failing = set()
    for number, line in numbered:
        project = project_of(line)
        versions = pip.versions(project)
        if allowed(line, versions):
            continue
        failing.add(number)
        errors.append(
            {
                "line": number,
                "project": project,
                "versions": versions,
                "available": ", ".join(versions[:MAX_SUGGESTIONS]) or "none",
            }
        )
    others_ok = [line for number, line in numbered if number not in failing]
    for error in errors:
        suggestions = []
        for candidate in error.pop("versions")[:MAX_TRIED_VERSIONS]:
            if resolves(
                pip, [*others_ok, f"{error['project']}=={candidate}"], constraints, scratch
            ):
                suggestions.append(candidate)
            if len(suggestions) == MAX_SUGGESTIONS:
                break
        error["suggestions"] = suggestions
    return errors


def missing_dependencies(output: str, numbered: list[list]) -> list[dict]:
    """Projects pip found no distribution for that no line names (a dependency of a line)."""
    listed = {project_of(line) for _, line in numbered}
    found = []
    for match in _NO_MATCH.finditer(output):
        project = project_of(match.group(1))
        if project in listed or any(e["project"] == project for e in found):
            continue
        versions = _FROM_VERSIONS.search(output[match.start() - 2048 : match.end()])
        shown = versions.group(1) if versions else "none"
        found.append({"line": None, "project": project, "available": shown, "suggestions": []})
    return found


def failure_tail(output: str) -> list[str]:
    """What pip's failure says that a team can act on: the distribution it was working on and
    the error's own lines (a build's output comes first), not pip's closing boilerplate."""
    lines = [line.rstrip() for line in output.strip().splitlines() if line.strip()]
    working = [line.strip() for line in lines if line.lstrip().startswith(_WORKING_ON)]
    start = next(
        (i for i, line in enumerate(lines) if line.lstrip().startswith(("×", "ERROR:", "error:"))),
        max(len(lines) - MAX_TAIL_LINES, 0),
    )
    told = [line.strip() for line in lines[start:] if not line.lstrip().startswith(_BOILERPLATE)]
    return working[-1:] + told[:MAX_TAIL_LINES]


def build_requires(sdist: Path) -> list[str]:
    """The sdist's ``[build-system] requires`` (setuptools' default when it has none), read
    without running anything."""
    text = None
    try:
        if sdist.name.endswith(".zip"):
            with zipfile.ZipFile(sdist) as archive:
                names = [n for n in archive.namelist() if n.count("/") == 1]
                name = next((n for n in names if n.endswith("/pyproject.toml")), None)
                text = archive.read(name).decode() if name else None
        else:
            with tarfile.open(sdist) as archive:
                member = next(
                    (
                        m
                        for m in archive.getmembers()
                        if m.name.count("/") == 1 and m.name.endswith("/pyproject.toml")
                    ),
                    None,
                )
                handle = archive.extractfile(member) if member is not None else None
                text = handle.read().decode() if handle is not None else None
        requires = tomllib.loads(text).get("build-system", {}).get("requires") if text else None
    except (OSError, ValueError, KeyError, tarfile.TarError, zipfile.BadZipFile):
        requires = None
    if not isinstance(requires, list) or not all(isinstance(r, str) for r in requires):
        return list(DEFAULT_BUILD_REQUIRES)
    return requires


def run_download(request: dict, output: Path, proxy_port: int | None) -> dict:
    pip = Pip(request, output, proxy_port)
    scratch = output / "tmp"
    numbered = request["requirements"]
    lines = [line for _, line in numbered]
    builds = cpu_builds(pip, lines, {project_of(line) for line in lines})
    constraints = [*request.get("constraints", []), *(f"{p}=={v}" for p, v in builds.items())]
    wheels = output / WHEELS_DIR
    failure = download(pip, lines, constraints, wheels, scratch)
    if not failure:
        suspects = gpu_builds_downloaded(wheels) - set(builds)
    elif FILE_TOO_LARGE in failure:
        # Maybe a GPU build past one wheel's cap, pulled in by a dependency.
        suspects = set(request.get("cpu_frameworks") or []) - set(builds)
    else:
        suspects = set()
    pulled_in = cpu_builds(pip, lines, suspects) if suspects else {}
    if pulled_in:
        # A dependency pulled in a framework's GPU build: once more, with its CPU build pinned.
        builds |= pulled_in
        constraints += [f"{p}=={v}" for p, v in pulled_in.items()]
        shutil.rmtree(wheels, ignore_errors=True)
        failure = download(pip, lines, constraints, wheels, scratch)
    if _LEGACY_FAILURE.search(failure) and legacy_build_env(pip, lines, constraints, output):
        # A legacy setup.py importing what it never declared: once more, against the usual ones.
        shutil.rmtree(wheels, ignore_errors=True)
        failure = download(pip, lines, constraints, wheels, scratch)
    if FILE_TOO_LARGE in failure:
        # The sandbox's file-size limit is one wheel's cap: pip's write past it failed.
        return {"ok": False, "cap": "max-wheel-bytes"}
    if failure:
        errors = unresolvable_lines(pip, numbered, constraints, scratch)
        errors += missing_dependencies(failure, numbered)
        return {
            "ok": False,
            "errors": errors,
            "conflict": conflict_block(failure),
            "tail": [] if errors else failure_tail(failure),
        }
    for wheel in wheels.glob("*.whl"):
        project, version = wheel.name.split("-")[:2]
        if project_of(project) in (request.get("cpu_frameworks") or []) and "+cpu" in version:
            builds[project_of(project)] = version  # what the page tells: the build installed
    sdists = [p for p in sorted(wheels.iterdir()) if p.name.endswith(SDIST_SUFFIXES)]
    if sdists:
        (output / SDISTS_DIR).mkdir()
        for sdist in sdists:
            sdist.rename(output / SDISTS_DIR / sdist.name)
        requires = sorted({r for s in sdists for r in build_requires(output / SDISTS_DIR / s.name)})
        (output / BUILD_DEPS_DIR).mkdir()
        code, failed = (
            (0, "")
            if not requires
            else pip.run(
                "download",
                "--progress-bar",
                "off",
                "--dest",
                str(output / BUILD_DEPS_DIR),
                *pip.target_options(binary_only=True),
                *pip.index_options(),
                "--",
                *requires,
            )
        )
        if code != 0:
            return {
                "ok": False,
                "errors": [],
                "conflict": [],
                "tail": [
                    "the build requirements of the source distributions:",
                    *failed.strip().splitlines()[-6:],
                ],
            }
    return {
        "ok": True,
        "wheels": sorted(p.name for p in wheels.glob("*.whl")),
        "sdists": [s.name for s in sdists],
        "cpu_builds": builds,
    }


def run_build(request: dict, source: Path, output: Path) -> dict:
    """Each sdist of ``source`` built into a wheel, with no network (``--no-index``) and only
    the build requirements downloaded before. Every sdist is tried, so that one upload names
    all that do not build, each with its own words."""
    pip = Pip(request, output, None)
    if (source / LEGACY_BUILD_ENV).is_dir():
        pip.use_build_env(source / LEGACY_BUILD_ENV)
    wheels = output / WHEELS_DIR
    built, failures = [], {}
    sdists = source / SDISTS_DIR
    for sdist in sorted(sdists.iterdir()) if sdists.is_dir() else []:
        code, failed = pip.run(
            "wheel",
            "--no-index",
            "--no-deps",
            *pip.isolation,
            "--find-links",
            str(source / BUILD_DEPS_DIR),
            "--wheel-dir",
            str(wheels),
            str(sdist),
        )
        if code == 0:
            built.append(sdist.name)
        else:
            failures[sdist.name] = failure_tail(failed)
    if failures:
        return {"ok": False, "errors": [], "conflict": [], "tail": build_failure_tail(failures)}
    return {"ok": True, "wheels": sorted(p.name for p in wheels.glob("*.whl")), "built": built}


def build_failure_tail(failures: dict[str, list[str]]) -> list[str]:
    """What the team is told of the sdists that did not build: their names, why a build can
    fail here, then each one's own words, the lines shared out among them."""
    names = ", ".join(failures)
    heading = (
        f"building {names} into {'a wheel' if len(failures) == 1 else 'wheels'} failed (no "
        "network, only its downloaded build requirements, a C/C++ compiler and Python's "
        "headers; a system library it needs is not there: ship a wheel of it instead):"
    )
    if len(failures) == 1:
        return [heading, *next(iter(failures.values()))]
    each = max(MIN_TAIL_LINES_EACH, MAX_TAIL_LINES // len(failures) - 1)
    return [heading] + [
        line for name, tail in failures.items() for line in (f"{name}:", *own_words(tail, each))
    ]


def own_words(tail: list[str], limit: int) -> list[str]:
    """``limit`` lines of a failed build from the first that its build said error in (the
    compiler's, a setup script's exception), past pip's framing around it."""
    start = next(
        (
            i
            for i, line in enumerate(tail)
            if _ERROR_WORD.search(line) and not line.lstrip().startswith(_PIP_FRAMING)
        ),
        0,
    )
    return tail[start : start + limit]


def main(argv: list[str]) -> int:
    """``MODE INPUT OUTPUT``: ``download`` or ``build``; the request in INPUT/resolve.json."""
    mode, source, output = argv[0], Path(argv[1]), Path(argv[2])
    request = json.loads((source / REQUEST).read_text())
    if request.get("pip_path"):
        sys.path.insert(0, request["pip_path"])
    if mode == "download":
        proxy = request.get("proxy")
        report = run_download(request, output, start_relay(proxy) if proxy else None)
    elif mode == "build":
        report = run_build(request, source, output)
    else:
        raise SystemExit(f"unknown mode {mode!r}")
    (output / REPORT).write_text(json.dumps(report))
    return 0


if __name__ == "__main__":
    os.umask(0o022)
    raise SystemExit(main(sys.argv[1:]))
