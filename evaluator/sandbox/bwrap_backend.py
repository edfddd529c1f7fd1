"""The bubblewrap backend, for hosts without Docker.

The agent gets empty namespaces of every kind (no network, its own pids and user namespace), a
root made of the host's ``/usr`` bound read-only (Debian's ``python3`` with ``python3-numpy``: the
same runtime as the agent image), size-capped tmpfs ``/tmp`` and ``/dev/shm``, a read-only
``/dev`` of the usual character devices, the seccomp filter of ``agent_runtime/confine.py``, and
only its submission and dependency folders, bound read-only. Memory, processes and CPU share are
those of a control group of its own (:mod:`evaluator.sandbox.cgroup`). Where no such group can be
made the sandbox falls back to per-process rlimits, which do not hold the contract: the service
refuses it then (:meth:`BubblewrapBackend.contract_gap`), local runs may still use it.

When the evaluator is root, bubblewrap runs as the unprivileged uid 65534, so that the process
limit holds (the kernel exempts root from it) and the agent is nobody on the host too. That uid
may not be able to reach the submission (pytest's or ``mkdtemp``'s private folders), so the
folders are first bound onto an open staging folder inside a private mount namespace
(``unshare --mount``), which vanishes with the sandbox and never shows on the host.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from agent_runtime import confine
from arena.child_env import child_environment
from arena.config import SandboxKind, SandboxSettings
from arena.errors import SandboxUnavailable
from evaluator.sandbox import cgroup
from evaluator.sandbox.backend import (
    DATASET_MOUNT,
    DEPS_MOUNT,
    MODEL_MOUNT,
    RUNTIME_MOUNT,
    SUBMISSION_MOUNT,
    LaunchSpec,
    runtime_dir,
)
from evaluator.sandbox.subprocess_sandbox import (
    LABELS_ENV,
    PopenSandbox,
    control_pair,
    encode_labels,
    kill_labelled,
    rlimit_setter,
    sandbox_streams,
)

RUNTIME_PYTHON = Path("/usr/bin/python3")
# The root is the host's /usr alone: /usr/local (the host's own tools) stays off the path.
SANDBOX_PATH = "/usr/bin:/bin"
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


# Runs as root in the sandbox's private mount namespace: bind each folder onto its staging point,
# then become uid/gid 65534 for good and start bubblewrap.
STAGE_SCRIPT = f"""set -e
while [ "$1" != -- ]; do mount --bind "$1" "$2"; shift 2; done
shift
exec setpriv --reuid={UNPRIVILEGED_ID} --regid={UNPRIVILEGED_ID} --clear-groups "$@"
"""


def staged(binds: dict[str, Path]) -> tuple[Path, dict[str, Path], list[str]]:
    """A staging folder, the staged sources, and the command prefix that binds them there."""
    stage = Path(tempfile.mkdtemp(prefix="arena-bwrap-"))
    stage.chmod(0o755)
    sources, pairs = {}, []
    for target, source in binds.items():
        point = stage / target.strip("/")
        point.mkdir(mode=0o755, parents=True)
        sources[target] = point
        pairs += [str(source), str(point)]
    prefix = ["unshare", "--mount", "--propagation", "private", "--", "sh", "-c", STAGE_SCRIPT]
    return stage, sources, [*prefix, "stage", *pairs, "--"]


class BubblewrapBackend:
    kind = SandboxKind.bubblewrap

    def unavailable_reason(self, config: SandboxSettings) -> str | None:
        if shutil.which("bwrap") is None:
            return "bubblewrap is not installed (apt-get install bubblewrap)"
        if os.geteuid() == 0 and not all(map(shutil.which, ("unshare", "setpriv", "mount"))):
            return "unshare, setpriv and mount are needed to drop to uid 65534 (util-linux)"
        if not RUNTIME_PYTHON.is_file():
            return f"{RUNTIME_PYTHON} is missing (apt-get install python3 python3-numpy)"
        probe = subprocess.run(
            [str(RUNTIME_PYTHON), "-I", "-c", "import numpy"], capture_output=True, timeout=60
        )
        if probe.returncode != 0:
            return f"{RUNTIME_PYTHON} has no numpy (apt-get install python3-numpy)"
        return None

    def contract_gap(self, config: SandboxSettings) -> str | None:
        """Why bubblewrap here does not hold the sandbox contract (docs/sandbox.md), or None."""
        reason = confine.supported() or cgroup.unavailable_reason()
        if reason:
            return f"bubblewrap here cannot enforce per-sandbox limits: {reason}"
        return None

    def launch(self, spec: LaunchSpec) -> PopenSandbox:
        config = spec.config
        binds = {RUNTIME_MOUNT: runtime_dir(), SUBMISSION_MOUNT: spec.submission}
        if spec.deps:
            binds[DEPS_MOUNT] = spec.deps
        if spec.training is not None:
            binds[DATASET_MOUNT] = spec.training.dataset
            binds[MODEL_MOUNT] = spec.training.output
            binds |= dict(spec.training.mounts)
        elif spec.model is not None:
            binds[MODEL_MOUNT] = spec.model
        training = spec.training is not None
        stage, prefix = None, []
        if os.geteuid() == 0:
            stage, binds, prefix = staged(binds)
        group = self._group(spec)
        control, child_end = control_pair(spec.zygote)
        seccomp = seccomp_fd(spec.seccomp_program())
        file_bytes = spec.training.output_bytes if spec.training is not None else None
        if group is not None:
            rlimits = rlimit_setter(None, None, file_bytes=file_bytes, cpus=spec.cpus)

            def preexec() -> None:
                group.join()
                rlimits()
        else:  # per process only: local runs (the service refuses this, see contract_gap)
            preexec = rlimit_setter(
                config.agent_memory_bytes,
                config.agent_pids,
                cpu_seconds=spec.cpu_seconds(),
                file_bytes=file_bytes,
                cpus=spec.cpus,
            )
        try:
            process = subprocess.Popen(
                [*prefix, *self.command(spec, binds, seccomp, group)],
                **sandbox_streams(training, child_end),
                cwd="/",
                env=child_environment({LABELS_ENV: encode_labels(spec.all_labels)}),
                start_new_session=True,
                pass_fds=(seccomp,),
                preexec_fn=preexec,
            )
        except (OSError, subprocess.SubprocessError) as error:
            if stage:
                shutil.rmtree(stage, ignore_errors=True)
            if group is not None:
                group.remove()
            raise SandboxUnavailable(f"cannot start bubblewrap: {error}") from error
        finally:
            os.close(seccomp)
            if child_end is not None:
                os.close(child_end)
        return PopenSandbox(
            process,
            config.agent_log_tail_bytes,
            spec.instance_labels,
            cleanup=stage,
            control=control,
            group=group,
        )

    @staticmethod
    def _group(spec: LaunchSpec) -> cgroup.SandboxGroup | None:
        """The sandbox's own control group, or None where none can be made."""
        found = cgroup.hierarchy()
        if not isinstance(found, cgroup.Hierarchy):
            return None
        config = spec.config
        limits = cgroup.Limits(
            config.agent_memory_bytes,
            config.agent_pids,
            config.agent_cpus,
        )
        return cgroup.SandboxGroup.create(found, cgroup.GROUP_PREFIX + spec.instance, limits)

    @staticmethod
    def command(
        spec: LaunchSpec,
        binds: dict[str, Path],
        seccomp: int,
        group: cgroup.SandboxGroup | None,
    ) -> list[str]:
        config = spec.config
        mounts = []
        for target, source in binds.items():
            writable = spec.training is not None and target == MODEL_MOUNT
            mounts += ["--bind" if writable else "--ro-bind", str(source), target]
        environment = []
        for key, value in spec.sandbox_env(SANDBOX_PATH).items():
            environment += ["--setenv", key, value]
        # A warm parent is the namespace's PID 1 itself: no signal from its children reaches it.
        as_pid_1 = ["--as-pid-1"] if spec.zygote else []
        if spec.zygote and group is not None:
            # Where it reads its OOM kills (agent_runtime/zygote.py oom_kills), read-only; its
            # children see an empty folder there.
            mounts += ["--ro-bind", str(group.memory_folder), group.memory_mount]
        return [
            "bwrap",
            "--unshare-all",
            *as_pid_1,
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
            "--remount-ro",
            "/dev",
            "--size",
            str(config.agent_tmp_bytes),
            "--tmpfs",
            "/dev/shm",
            "--size",
            str(config.agent_tmp_bytes),
            "--tmpfs",
            "/tmp",
            *mounts,
            "--remount-ro",
            "/",
            "--chdir",
            SUBMISSION_MOUNT,
            "--clearenv",
            # Inside too, so cleanup() finds the agent's own processes, not just bwrap.
            "--setenv",
            LABELS_ENV,
            encode_labels(spec.all_labels),
            *environment,
            "--seccomp",
            str(seccomp),
            str(RUNTIME_PYTHON),
            *spec.python_args(),
        ]

    def cleanup(self, labels: dict[str, str], config: SandboxSettings) -> int:
        killed = kill_labelled(labels)
        cgroup.remove_orphans()
        return killed


def seccomp_fd(program: bytes) -> int:
    """A descriptor bubblewrap reads the filter from (``--seccomp``)."""
    fd = os.memfd_create("arena-seccomp")
    os.write(fd, program)
    os.lseek(fd, 0, os.SEEK_SET)
    return fd
