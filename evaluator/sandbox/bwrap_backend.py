"""The bubblewrap backend, for hosts without Docker.

The agent gets empty namespaces of every kind (no network, its own pids), a root made of the host's
``/usr`` bound read-only (Debian's ``python3`` with ``python3-numpy``: the same runtime as the
agent image), a size-capped tmpfs ``/tmp``, and only its submission and dependency folders, bound
read-only through file descriptors. Memory and process counts are capped with rlimits; bubblewrap
itself runs as the unprivileged uid 65534 when the evaluator is root, so the process limit counts
against that user and not against root (which the kernel exempts).
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
from pathlib import Path

from arena.config import SandboxKind, Settings
from evaluator.errors import SandboxUnavailable
from evaluator.sandbox.backend import (
    DEPS_MOUNT,
    RUNNER_MOUNT,
    RUNNER_PATH,
    RUNTIME_ENV,
    SUBMISSION_MOUNT,
    LaunchSpec,
)
from evaluator.sandbox.subprocess_sandbox import (
    LABELS_ENV,
    PopenSandbox,
    encode_labels,
    kill_labelled,
    rlimit_setter,
)

RUNTIME_PYTHON = Path("/usr/bin/python3")
UNPRIVILEGED_ID = 65534
# Debian finds BLAS through /etc/alternatives symlinks; nothing else of /etc is bound.
ETC_NEEDED = ("/etc/alternatives", "/etc/ld.so.cache")
# Top-level directories of a merged-/usr Debian root; real directories on older layouts.
USR_ALIASES = ("bin", "sbin", "lib", "lib32", "lib64", "libx32")


def root_layout() -> list[str]:
    arguments = ["--ro-bind", "/usr", "/usr"]
    for name in USR_ALIASES:
        host = Path("/") / name
        if host.is_symlink():
            arguments += ["--symlink", os.readlink(host), f"/{name}"]
        elif host.is_dir():
            arguments += ["--ro-bind", str(host), f"/{name}"]
    for path in ETC_NEEDED:
        arguments += ["--ro-bind-try", path, path]
    return arguments


def require_reachable(path: Path) -> None:
    """bubblewrap binds as uid 65534: every folder above ``path`` must let others enter it."""
    if os.geteuid() != 0:
        return
    for folder in [*reversed(path.parents), path]:
        mode = folder.stat().st_mode
        if not mode & stat.S_IXOTH or (folder == path and not mode & stat.S_IROTH):
            raise SandboxUnavailable(
                f"the bubblewrap sandbox runs as uid {UNPRIVILEGED_ID}, which cannot enter "
                f"{folder} (mode {stat.S_IMODE(mode):o}): keep submissions and the data dir "
                f"under folders others may enter (chmod o+rx)"
            )


class BubblewrapBackend:
    kind = SandboxKind.bubblewrap

    def unavailable_reason(self, settings: Settings) -> str | None:
        if shutil.which("bwrap") is None:
            return "bubblewrap is not installed (apt-get install bubblewrap)"
        if not RUNTIME_PYTHON.is_file():
            return f"{RUNTIME_PYTHON} is missing (apt-get install python3 python3-numpy)"
        probe = subprocess.run(
            [str(RUNTIME_PYTHON), "-I", "-c", "import numpy"], capture_output=True, timeout=60
        )
        if probe.returncode != 0:
            return f"{RUNTIME_PYTHON} has no numpy (apt-get install python3-numpy)"
        return None

    def launch(self, spec: LaunchSpec) -> PopenSandbox:
        settings = spec.settings
        binds = {SUBMISSION_MOUNT: spec.submission}
        if spec.deps:
            binds[DEPS_MOUNT] = spec.deps
        for source in binds.values():
            require_reachable(source)
        # The runner goes in as data read from a descriptor: it may live under a root-only
        # prefix (a virtualenv in /root) that uid 65534 cannot enter.
        runner_fd = os.open(RUNNER_PATH, os.O_RDONLY | os.O_CLOEXEC)
        dropping = os.geteuid() == 0
        try:
            process = subprocess.Popen(
                self.command(spec, binds, runner_fd),
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                cwd="/",
                env={"PATH": os.defpath, LABELS_ENV: encode_labels(spec.all_labels)},
                pass_fds=(runner_fd,),
                start_new_session=True,
                preexec_fn=rlimit_setter(settings.agent_memory_bytes, settings.agent_pids),
                user=UNPRIVILEGED_ID if dropping else None,
                group=UNPRIVILEGED_ID if dropping else None,
                extra_groups=[] if dropping else None,
            )
        except OSError as error:
            raise SandboxUnavailable(f"cannot start bubblewrap: {error}") from error
        finally:
            os.close(runner_fd)
        return PopenSandbox(process, settings.agent_log_tail_bytes, spec.instance_labels)

    @staticmethod
    def command(spec: LaunchSpec, binds: dict[str, Path], runner_fd: int) -> list[str]:
        settings = spec.settings
        mounts = ["--perms", "0444", "--ro-bind-data", str(runner_fd), RUNNER_MOUNT]
        for target, source in binds.items():
            mounts += ["--ro-bind", str(source), target]
        environment = []
        for key, value in RUNTIME_ENV.items():
            environment += ["--setenv", key, value]
        return [
            "bwrap",
            "--unshare-all",
            "--die-with-parent",
            "--new-session",
            "--cap-drop",
            "ALL",
            "--uid",
            str(UNPRIVILEGED_ID),
            "--gid",
            str(UNPRIVILEGED_ID),
            "--hostname",
            "agent",
            *root_layout(),
            "--proc",
            "/proc",
            "--dev",
            "/dev",
            "--size",
            str(settings.agent_tmp_bytes),
            "--tmpfs",
            "/tmp",
            "--dir",
            "/opt/arena",
            *mounts,
            "--remount-ro",
            "/",
            "--chdir",
            SUBMISSION_MOUNT,
            "--clearenv",
            "--setenv",
            "PATH",
            "/usr/bin:/bin",
            # Inside too, so cleanup() finds the agent's own processes, not just bwrap.
            "--setenv",
            LABELS_ENV,
            encode_labels(spec.all_labels),
            *environment,
            str(RUNTIME_PYTHON),
            *spec.runner_args(),
        ]

    def cleanup(self, labels: dict[str, str]) -> int:
        return kill_labelled(labels)
