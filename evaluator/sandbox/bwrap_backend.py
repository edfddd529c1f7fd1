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
        bound = {SUBMISSION_MOUNT: spec.submission, RUNNER_MOUNT: RUNNER_PATH}
        if spec.deps:
            bound[DEPS_MOUNT] = spec.deps
        # Bound through descriptors opened here, so the unprivileged bwrap needs no search
        # permission on the folders above them (pytest's 0700 tmp, a root-only data dir).
        fds = {
            target: os.open(source, os.O_PATH | os.O_CLOEXEC) for target, source in bound.items()
        }
        try:
            command = self.command(spec, fds)
            dropping = os.geteuid() == 0
            process = subprocess.Popen(
                command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                cwd="/",
                env={"PATH": os.defpath, LABELS_ENV: encode_labels(spec.all_labels)},
                pass_fds=tuple(fds.values()),
                start_new_session=True,
                preexec_fn=rlimit_setter(settings.agent_memory_bytes, settings.agent_pids),
                user=UNPRIVILEGED_ID if dropping else None,
                group=UNPRIVILEGED_ID if dropping else None,
                extra_groups=[] if dropping else None,
            )
        except OSError as error:
            raise SandboxUnavailable(f"cannot start bubblewrap: {error}") from error
        finally:
            for fd in fds.values():
                os.close(fd)
        return PopenSandbox(process, settings.agent_log_tail_bytes)

    @staticmethod
    def command(spec: LaunchSpec, fds: dict[str, int]) -> list[str]:
        settings = spec.settings
        binds = []
        for target, fd in fds.items():
            binds += ["--ro-bind-fd", str(fd), target]
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
            *binds,
            "--remount-ro",
            "/",
            "--chdir",
            SUBMISSION_MOUNT,
            "--clearenv",
            "--setenv",
            "PATH",
            "/usr/bin:/bin",
            *environment,
            str(RUNTIME_PYTHON),
            *spec.runner_args(),
        ]

    def cleanup(self, labels: dict[str, str]) -> int:
        return kill_labelled(labels)
