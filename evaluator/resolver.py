"""The resolver sandbox: a team's requirements resolved, downloaded and built only here.

:func:`spawn_resolver` is the one way the service starts a resolver child
(``agent_runtime/resolve.py``). It runs in the backend agents run in (bubblewrap or Docker), as
uid 65534, with the sandbox's explicit environment (``LaunchSpec.sandbox_env``: nothing of the
host's, no secret), the runtime, the evaluator's own pip (and its CA bundle, where a distribution
keeps it apart) and the package index's folders bound read-only, its request as its only input
and one writable output folder; memory (``resolver_memory_bytes``), wall time
(``resolver_timeout_s``), one file's size (``max_wheel_bytes``) and the output's bytes
(``max_deps_download_bytes``) capped.

Its network namespace has loopback only. In ``download`` mode its way out is the host's
:class:`~evaluator.sandbox.index_proxy.IndexProxy`, whose socket is bound in and which reaches
the package index's hosts and nothing else; in ``build`` mode (sdists into wheels) there is no
way out at all. Under Docker, ``build`` mode runs in the builder image
(``SandboxSettings.builder_image``: the agent's Python with a C/C++ toolchain and its headers),
so sdists with extensions build without a compiler in the image that runs policies; a daemon
without that image is ours to fix (:class:`~arena.errors.SandboxUnavailable`), never the team's.
"""

from __future__ import annotations

import importlib.util
import json
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

from agent_runtime import resolve
from arena.config import IntakeSettings, SandboxKind, SandboxSettings
from arena.errors import IntakeError, SandboxUnavailable
from evaluator import sandbox
from evaluator.sandbox.backend import (
    DATASET_MOUNT,
    MODEL_MOUNT,
    RUNTIME_MOUNT,
    TRAIN_SCRIPT,
    Sandbox,
    Training,
)
from evaluator.sandbox.batch_folders import open_to_sandbox, output_usage, writable_by_sandbox
from evaluator.sandbox.docker_backend import missing_image_reason
from evaluator.sandbox.index_proxy import IndexProxy, allowed_address
from submissions.intake.contents import REQUIREMENTS
from submissions.intake.package_index import local_path
from submissions.intake.runner import read_resolver_report

POLL_S = 0.2
PIP_MOUNT = "/opt/resolver-pip"
PROXY_MOUNT = "/run/arena-index"
PROXY_SOCKET = "proxy.sock"
# pip starts a child per build and per metadata hook: more processes than an agent needs.
RESOLVER_PIDS = 256
# Room beyond the download cap: pip's temporary copies and the sdists' build requirements.
SCRATCH_BYTES = 256 * 1024**2


def host_pip() -> Path:
    """The evaluator's own pip (a pure-Python package): the resolver's, whatever the image has."""
    spec = importlib.util.find_spec("pip")
    if spec is None or not spec.submodule_search_locations:
        raise SandboxUnavailable("pip is not installed beside the evaluator")
    return Path(next(iter(spec.submodule_search_locations)))


def pip_ca_bundle(pip: Path) -> str | None:
    """The CA bundle the evaluator's pip checks HTTPS with, when it lies outside ``pip``'s
    folder (Debian's pip reads the system's, ``/etc/ssl/certs/ca-certificates.crt``): bound as a
    configured ``cert`` is, or pip in the sandbox finds no bundle and stops at the first HTTPS
    index. None when pip carries its own (bound with it)."""
    # deferred: pip's vendored certifi, patched by distributions that debundle it
    from pip._vendor import certifi

    bundle = Path(certifi.where()).resolve()
    return None if bundle.is_relative_to(pip.resolve()) else str(bundle)


def _stub(mode: str) -> str:
    return (
        "import runpy, sys\n"
        f"sys.argv = ['resolve.py', {mode!r}, {DATASET_MOUNT!r}, {MODEL_MOUNT!r}]\n"
        f"runpy.run_path({RUNTIME_MOUNT + '/resolve.py'!r}, run_name='__main__')\n"
    )


def resolver_mounts(
    request: dict, pip: Path, proxy_dir: Path | None
) -> tuple[tuple[str, Path], ...]:
    """``pip``, the proxy's socket folder (download only) and the index's folders (at their own
    paths, so ``file:`` URLs and relative links read the same inside)."""
    mounts = [(f"{PIP_MOUNT}/pip", pip)]
    if proxy_dir is not None:
        mounts.append((PROXY_MOUNT, proxy_dir))
    for location in [*request["index_urls"], *request["find_links"]]:
        path = local_path(location)
        if path is None:
            continue
        folder = path if location in request["find_links"] and path.is_dir() else path.parent
        if folder.is_dir():
            mounts.append((str(folder), folder))
    if request.get("cert"):
        mounts.append((str(Path(request["cert"]).parent), Path(request["cert"]).parent))
    return tuple(dict(mounts).items())


def index_addresses(request: dict) -> set[tuple[str, int]]:
    """The ``(host, port)`` the proxy lets the resolver reach: the index's and its file hosts."""
    addresses = {allowed_address(u) for u in [*request["index_urls"], *request["find_links"]]}
    addresses |= {(host, 443) for host in request.get("file_hosts", [])}
    return {a for a in addresses if a is not None}


def resolver_image(mode: str, kind: SandboxKind, config: SandboxSettings) -> str:
    """The image a Docker resolver runs in: the builder for ``build`` (sdists need a compiler
    and Python's headers), the agent's otherwise. Raises
    :class:`~arena.errors.SandboxUnavailable` when the daemon lacks the builder."""
    if mode != "build" or kind is not SandboxKind.docker:
        return config.agent_image
    if missing := missing_image_reason(config.builder_image, "the resolver's sdist builder"):
        raise SandboxUnavailable(missing)
    return config.builder_image


def spawn_resolver(
    mode: str,
    inputs: Path,
    output: Path,
    program: Path,
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
    proxy_dir: Path | None = None,
) -> Sandbox:
    """Start the resolver (``mode``: ``download`` or ``build``) on ``inputs/resolve.json``,
    writing to ``output``; ``program`` is an empty folder for its stub, ``proxy_dir`` the folder
    of the index proxy's socket (download only). The request is rewritten for the sandbox:
    where pip and the proxy are, and no target options (pip runs on the agent's interpreter)."""
    chosen = sandbox.resolve_kind(kind, config)
    if chosen is SandboxKind.process:
        raise SandboxUnavailable("the resolver runs only in a sandbox (docker or bubblewrap)")
    request = json.loads((inputs / resolve.REQUEST).read_text())
    pip = host_pip()
    request |= {
        "pip_path": PIP_MOUNT,
        "proxy": f"{PROXY_MOUNT}/{PROXY_SOCKET}" if proxy_dir is not None else None,
        "target": [],
        "cert": request.get("cert") or pip_ca_bundle(pip),
    }
    (inputs / resolve.REQUEST).write_text(json.dumps(request))
    (program / TRAIN_SCRIPT).write_text(_stub(mode))
    open_to_sandbox(program, inputs)
    writable_by_sandbox(output)
    limits = config.model_copy(
        update={
            "agent_memory_bytes": intake.resolver_memory_bytes,
            "agent_pids": max(config.agent_pids, RESOLVER_PIDS),
            "agent_image": resolver_image(mode, chosen, config),
        }
    )
    batch = Training(
        inputs,
        output,
        intake.resolver_timeout_s,
        intake.max_wheel_bytes,
        # Host folders: a worker in a container has the Docker backend bind copies of them
        # (docker_backend.daemon_source).
        mounts=resolver_mounts(request, pip, proxy_dir),
    )
    return sandbox.start_training(
        SimpleNamespace(root=program, deps_dir=None),
        batch,
        config=limits,
        data_dir=data_dir,
        kind=chosen,
        labels=labels,
    )


def run_resolver(
    mode: str,
    inputs: Path,
    output: Path,
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
) -> dict:
    """One resolver step to its end, within its bounds; its report (``agent_runtime/resolve``).
    A step past a bound is rejected naming it (``resolver-timeout``, ``max-deps-download``,
    ``resolver-memory``); one that crashes is ``resolver-crashed``."""
    shared = config.sandbox_shared_dir
    if shared is not None:
        shared.mkdir(parents=True, exist_ok=True)
    disk_cap = intake.max_deps_download_bytes + SCRATCH_BYTES
    with tempfile.TemporaryDirectory(prefix="arena-resolver-", dir=shared) as scratch:
        program, proxy_dir = Path(scratch) / "program", Path(scratch) / "proxy"
        program.mkdir()
        proxy_dir.mkdir()
        proxy_dir.chmod(0o755)
        request = json.loads((inputs / resolve.REQUEST).read_text())
        proxy = (
            IndexProxy(proxy_dir / PROXY_SOCKET, index_addresses(request))
            if mode == "download"
            else None
        )
        try:
            if proxy is not None:
                # The sandbox's uid connects to it.
                (proxy_dir / PROXY_SOCKET).chmod(0o777)
            box = spawn_resolver(
                mode,
                inputs,
                output,
                program,
                intake=intake,
                config=config,
                data_dir=data_dir,
                kind=kind,
                labels=labels,
                proxy_dir=proxy_dir if proxy is not None else None,
            )
            started = time.monotonic()
            try:
                while (status := box.exit_status(POLL_S)) is None:
                    if time.monotonic() - started > intake.resolver_timeout_s:
                        raise IntakeError(
                            REQUIREMENTS,
                            "resolver-timeout",
                            f"resolving the requirements took longer than "
                            f"{intake.resolver_timeout_s:g} s",
                        )
                    if output_usage(output)[0] > disk_cap:
                        raise IntakeError(
                            REQUIREMENTS,
                            "max-deps-download",
                            "the requirements' downloads are larger than "
                            f"{intake.max_deps_download_bytes / 1024**2:g} MiB",
                        )
            finally:
                box.kill()
            log = box.logs()
        finally:
            if proxy is not None:
                proxy.close()
    if status.oom_killed or (status.code != 0 and "MemoryError" in log):
        raise IntakeError(
            REQUIREMENTS,
            "resolver-memory",
            f"resolving needed more than {intake.resolver_memory_bytes // 1024**2} MiB",
        )
    if status.code != 0:
        raise IntakeError(REQUIREMENTS, "resolver-crashed", f"the resolver {status.describe()}")
    return read_resolver_report(output)
