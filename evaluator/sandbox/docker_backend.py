"""The Docker backend: one locked-down container per agent.

:func:`container_options` is the only place a container is described, so every container gets
every safety option. The protocol does not go through the Docker daemon: the container connects to
a unix socket in a per-agent folder mounted into it, so a step costs two socket writes, no HTTP.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import select
import shutil
import socket
import tempfile
import time
from functools import lru_cache
from pathlib import Path
from typing import Any

from agent_runtime import confine
from arena.config import SandboxKind, SandboxSettings
from arena.errors import SandboxUnavailable
from evaluator.sandbox.backend import (
    DATASET_MOUNT,
    DEPS_MOUNT,
    INSTANCE_LABEL,
    MODEL_MOUNT,
    RUNTIME_MOUNT,
    SANDBOX_LABEL,
    SUBMISSION_MOUNT,
    ExitStatus,
    LaunchSpec,
    runtime_dir,
    signal_name,
)
from evaluator.sandbox.channel import Channel, ChannelClosed, ChannelTimeout
from evaluator.sandbox.cpu import CpuMeter, cgroup_meter
from evaluator.sandbox.placement import cpuset

SOCKET_MOUNT = "/run/arena"
SOCKET_NAME = "agent.sock"
UNPRIVILEGED_ID = 65534
UNPRIVILEGED_USER = f"{UNPRIVILEGED_ID}:{UNPRIVILEGED_ID}"
# Docker's default: the agent image's python3 is in /usr/local/bin (Dockerfile.agent) or /usr/bin
# (the offline image).
IMAGE_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
# The log driver keeps this much per container; we show the last agent_log_tail_bytes of it.
LOG_MAX_SIZE = "1m"
# OCI runtimes that run the container on a kernel of their own in user space (gVisor's runsc),
# and the host tasks that kernel needs: measured on the ptrace platform, 66 with one idle agent
# process and 306 with 51 (about 5 per process, none per thread), so twice that as the bound.
USER_SPACE_KERNELS = frozenset({"runsc"})
USER_SPACE_KERNEL_TASKS = 128
USER_SPACE_KERNEL_TASKS_PER_PROCESS = 10
# How long a killed container may take to be reported dead [s].
KILL_WAIT_S = 10.0
# How often a starting container is checked for having died before it connected [s].
START_POLL_S = 0.1
# Socket folders are named after their container's instance label, so that cleanup can remove
# those a killed worker left behind; a younger one may belong to a container still being created.
SOCKET_DIR_PREFIX = "arena-agent-"
ORPHAN_SOCKET_DIR_AGE_S = 60.0
# The shared folder's copies of folders the daemon cannot see (shared_copy), and how long one
# stays unused before the cleanup removes it: longer than any episode, training or validation
# binds it.
COPIES_DIR = "copies"
STALE_COPY_AGE_S = 24 * 3600.0
STALE_PREFIX = ".stale-"


def socket_dir_for(instance: str, shared: Path | None) -> Path:
    """Where the protocol socket of sandbox ``instance`` is made: in the shared folder
    (``ARENA_SANDBOX_SHARED_DIR``) when there is one."""
    root = Path(tempfile.gettempdir()) if shared is None else shared
    return root / f"{SOCKET_DIR_PREFIX}{instance}"


def daemon_source(folder: Path, spec: LaunchSpec) -> Path:
    """The host folder the daemon binds to show ``folder`` read-only in ``spec``'s container:
    ``folder`` itself, or, with ``ARENA_SANDBOX_SHARED_DIR`` (a worker in a container, whose own
    folders the host's daemon cannot see), for a folder outside the shared and the data folder
    (both at the same path on either side), its copy in the shared folder. Every read-only bind
    goes through here, so a folder of the worker's image (the agent runtime, the resolver's pip,
    a wheel folder or a ``file:`` index of its pip configuration, the certificates) reaches the
    container whoever asks for it."""
    shared = spec.config.sandbox_shared_dir
    if shared is None:
        return folder
    real = folder.resolve()
    if any(real.is_relative_to(seen.resolve()) for seen in (shared, spec.data_dir)):
        return folder
    return shared_copy(real, shared, real.name or "root")


# shared_copy's memo per process: (folder, shared folder, name) -> (the folder's stat signature,
# its copy). The copy is named after the content's digest, which reads every byte, and a wheel
# folder can hold GBs that every resolution binds: a folder whose files keep their inode, size,
# mtime and ctime (ctime cannot be set back, unlike mtime) keeps its digest, so only a stat per
# file is repeated. One entry per folder, the latest: the memo stays as small as the set of
# folders; two threads racing on it at worst both hash.
_COPIES: dict[tuple[Path, Path, str], tuple[tuple, Path]] = {}


def shared_copy(package: Path, shared: Path | None, name: str) -> Path:
    """The folder ``package`` as the daemon can bind it: itself, or, with a shared folder (a
    worker in a container), a copy in its ``copies`` folder named ``name`` and its content's
    digest (several workers and threads make it at once: each copies, then renames), readable by
    everyone (the sandbox's uid 65534). Each use touches the copy; each new copy, and the
    sandbox cleanup, removes those no launch used for a day (:func:`remove_stale_copies`: a new
    image's wheels leave the old ones behind)."""
    if shared is None:
        return package
    files = sorted(p for p in package.rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    signature = tuple(_stamp(package, path) for path in files)
    key = (package, shared, name)
    known = _COPIES.get(key)
    if known is not None and known[0] == signature and _used(known[1]):
        return known[1]
    digest = hashlib.sha256()
    for path in files:
        digest.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes())
    copies = shared / COPIES_DIR
    target = copies / f"{name}-{digest.hexdigest()[:16]}"
    if not _used(target):
        # The first launch may be an upload's validation, before any agent made the folder.
        copies.mkdir(parents=True, exist_ok=True)
        partial = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=copies))
        for path in files:
            (partial / path.relative_to(package)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, partial / path.relative_to(package))
        for path in [partial, *partial.rglob("*")]:
            path.chmod(0o755 if path.is_dir() else 0o644)
        try:
            partial.rename(target)
        except OSError:  # another process made it first
            shutil.rmtree(partial, ignore_errors=True)
        # A folder's content changed (a new image's wheels): its old copy may now go unused.
        remove_stale_copies(shared)
    _COPIES[key] = (signature, target)
    return target


def _used(copy: Path) -> bool:
    """Mark ``copy`` as used now; False when it is not there (never made, or removed stale)."""
    try:
        os.utime(copy)
    except FileNotFoundError:
        return False
    return True


def remove_stale_copies(shared: Path | None) -> int:
    """Remove the shared folder's copies (and half-made ones) no launch used for
    :data:`STALE_COPY_AGE_S`; how many. Each is renamed out of the way first, so that a launch
    never binds a folder half removed: it makes the copy again."""
    if shared is None or not (copies := shared / COPIES_DIR).is_dir():
        return 0
    cutoff = time.time() - STALE_COPY_AGE_S
    removed = 0
    for path in copies.iterdir():
        # Another worker's cleanup may take the same copy first.
        with contextlib.suppress(OSError):
            if path.name.startswith(STALE_PREFIX):  # a removal that did not finish
                shutil.rmtree(path, ignore_errors=True)
            elif path.stat().st_mtime < cutoff:
                doomed = path.rename(copies / f"{STALE_PREFIX}{path.name.lstrip('.')}")
                shutil.rmtree(doomed, ignore_errors=True)
                removed += 1
    return removed


def _stamp(package: Path, path: Path) -> tuple[str, int, int, int, int]:
    status = path.stat()
    relative = str(path.relative_to(package))
    return relative, status.st_ino, status.st_size, status.st_mtime_ns, status.st_ctime_ns


def remove_orphan_socket_dirs(live_instances: set[str], shared: Path | None) -> None:
    cutoff = time.time() - ORPHAN_SOCKET_DIR_AGE_S
    for path in socket_dir_for("", shared).parent.glob(f"{SOCKET_DIR_PREFIX}*"):
        orphan = path.name.removeprefix(SOCKET_DIR_PREFIX) not in live_instances
        with contextlib.suppress(FileNotFoundError):
            if orphan and path.stat().st_mtime < cutoff:
                shutil.rmtree(path, ignore_errors=True)


def remove_binding(folders: list[Path], labels: dict[str, str]) -> int:
    """Remove the containers carrying ``labels`` (running or stopped) that bind anything in one
    of ``folders``; how many. A container outlives the process that started it (bubblewrap's
    sandboxes die with theirs), so a worker process that died (SIGKILL, the OOM killer) leaves
    its agents' and intakes' containers behind: its successor finds them by the dead process's
    scratch folder. Matched by each folder's last two parts (``scratch/<host>-<pid>``): a
    containerised worker may see the data folder under another path than the daemon does."""
    # deferred: the docker client is needed only with the Docker sandbox
    import docker.errors
    import requests.exceptions

    tails = [f"/{folder.parent.name}/{folder.name}/" for folder in folders]
    selector = [f"{key}={value}" for key, value in labels.items()]
    removed = 0
    try:
        # Sparse: the listing's own mounts, no inspection that a container ending meanwhile fails.
        listed = docker_client().containers.list(all=True, sparse=True, filters={"label": selector})
        for container in listed:
            sources = [m.get("Source", "") for m in container.attrs.get("Mounts") or []]
            if any(tail in f"{source}/" for source in sources for tail in tails):
                with contextlib.suppress(docker.errors.NotFound):
                    container.remove(force=True)
                    removed += 1
    except (docker.errors.DockerException, requests.exceptions.RequestException):
        return removed  # no daemon, no containers
    return removed


@lru_cache
def docker_client():
    # deferred: the docker client is needed only with the Docker sandbox
    import docker

    return docker.from_env()


def missing_image_reason(image: str, purpose: str) -> str | None:
    """Why the daemon cannot run containers of ``image`` (needed for ``purpose``); None when it
    has it."""
    # deferred: the docker client is needed only with the Docker sandbox
    import docker.errors

    try:
        docker_client().images.get(image)
    except docker.errors.ImageNotFound:
        return f"image {image} ({purpose}) is missing (run `arena sandbox build-image`)"
    except docker.errors.DockerException as error:
        return f"no Docker daemon answers ({error})"
    return None


def container_options(spec: LaunchSpec, socket_dir: Path | None) -> dict[str, Any]:
    """Everything ``containers.run`` gets; the safety options are not negotiable. A training run
    (``spec.training``) has no protocol socket: it gets the dataset read-only, the output folder
    writable with no single file larger than its cap, and the GPUs when the organisers enable
    them."""
    # deferred: the docker client is needed only with the Docker sandbox
    from docker.types import DeviceRequest, LogConfig, Ulimit

    config = spec.config
    # (host folder, where the container sees it): bound read-only, as the daemon sees it.
    readonly = [(spec.submission, SUBMISSION_MOUNT), (runtime_dir(), RUNTIME_MOUNT)]
    # Bound as they are: they must already be where the daemon sees them.
    live: dict[str, dict[str, str]] = {}
    if spec.deps:
        readonly.append((spec.deps, DEPS_MOUNT))
    command = ["python3", *spec.python_args()]
    extra: dict[str, Any] = {}
    ulimits = []
    pids_limit = config.agent_pids
    if config.docker_runtime:
        extra["runtime"] = config.docker_runtime
    if spec.cpus is not None:
        # Its job's CPUs (evaluator.sandbox.placement), beside the quota, which stays nano_cpus.
        extra["cpuset_cpus"] = cpuset(spec.cpus)
    if config.docker_runtime in USER_SPACE_KERNELS:
        # The container's cgroup holds gVisor's kernel (its threads, its ptrace stubs), not the
        # agent's processes one for one: the agent's are counted by that kernel, per uid, and
        # every sandbox has a kernel of its own, so RLIMIT_NPROC is a per-sandbox limit there.
        ulimits.append(Ulimit(name="nproc", soft=config.agent_pids, hard=config.agent_pids))
        pids_limit = USER_SPACE_KERNEL_TASKS + USER_SPACE_KERNEL_TASKS_PER_PROCESS * pids_limit
    if spec.training is not None:
        readonly.append((spec.training.dataset, DATASET_MOUNT))
        readonly += [(source, target) for target, source in spec.training.mounts]
        # Written by the container: a copy would swallow what it writes.
        live[str(spec.training.output)] = {"bind": MODEL_MOUNT, "mode": "rw"}
        cap = spec.training.output_bytes
        ulimits.append(Ulimit(name="fsize", soft=cap, hard=cap))
        if spec.training.gpu:
            extra["device_requests"] = [DeviceRequest(count=-1, capabilities=[["gpu"]])]
    else:
        if spec.model is not None:
            readonly.append((spec.model, MODEL_MOUNT))
        assert socket_dir is not None
        # A socket, not a copy: socket_dir_for makes it in the shared folder.
        live[str(socket_dir)] = {"bind": SOCKET_MOUNT, "mode": "ro"}
        command += ["--socket", f"{SOCKET_MOUNT}/{SOCKET_NAME}"]
    volumes = {
        str(daemon_source(folder, spec)): {"bind": target, "mode": "ro"}
        for folder, target in readonly
    }
    return {
        "image": config.agent_image,
        "command": command,
        "detach": True,
        # A warm parent is the container's PID 1 itself: no signal from its children reaches
        # it, and it reaps their orphans as the init would.
        "init": not spec.zygote,
        "network_mode": "none",
        "read_only": True,
        "tmpfs": {"/tmp": f"rw,nosuid,nodev,size={config.agent_tmp_bytes},mode=1777"},
        "mem_limit": config.agent_memory_bytes,
        "memswap_limit": config.agent_memory_bytes,
        "nano_cpus": int(config.agent_cpus * 1e9),
        "pids_limit": pids_limit,
        "ulimits": ulimits,
        "cap_drop": ["ALL"],
        "security_opt": ["no-new-privileges", f"seccomp={spec.seccomp_profile()}"],
        "user": UNPRIVILEGED_USER,
        "ipc_mode": "none",
        "working_dir": SUBMISSION_MOUNT,
        "environment": spec.sandbox_env(IMAGE_PATH),
        "volumes": volumes | live,
        "labels": spec.all_labels,
        "log_config": LogConfig(
            type="json-file", config={"max-size": LOG_MAX_SIZE, "max-file": "1"}
        ),
        **extra,
    }


def share_with_agent(socket_dir: Path, path: Path) -> None:
    """Let the container's group 65534 (and, when we cannot chown, everyone) reach the socket."""
    if os.geteuid() == 0:
        os.chown(socket_dir, -1, UNPRIVILEGED_ID)
        os.chown(path, -1, UNPRIVILEGED_ID)
        socket_dir.chmod(0o750)
        path.chmod(0o660)
    else:
        socket_dir.chmod(0o755)
        path.chmod(0o777)


def daemon_stop(container_id: str, since: float, until: float) -> str:
    """How the Docker daemon was told to stop container ``container_id`` between ``since`` and
    ``until`` (``docker kill``, ``stop``, ``rm -f``, its own shutdown), as its events say: "the
    Docker daemon (SIGKILL)", or "" when it was not (what ended the container happened inside
    it, or the daemon cannot say)."""
    # deferred: the docker client is needed only with the Docker sandbox
    import docker.errors
    import requests.exceptions

    try:
        events = docker_client().events(
            since=f"{since:.6f}",
            until=f"{until:.6f}",
            filters={"container": container_id, "event": "kill"},
            decode=True,
        )
        for event in events:
            number = event.get("Actor", {}).get("Attributes", {}).get("signal", "")
            return f"the Docker daemon ({signal_name(int(number)) if number.isdigit() else number})"
    except (docker.errors.DockerException, requests.exceptions.RequestException):
        pass
    return ""


class DockerSandbox:
    def __init__(
        self,
        container,
        listener: socket.socket | None,
        socket_dir: Path | None,
        log_limit: int,
        launched: float,
    ):
        self.container = container
        self.launched = launched  # [s] time.time() before the container was created
        self._listener = listener
        self._socket_dir = socket_dir
        self._log_limit = log_limit
        self._connection: socket.socket | None = None
        self._final_logs: str | None = None
        self._killed_at: float | None = None  # when we killed it: later kills are ours
        self._status: ExitStatus | None = None

    def connect(self, deadline: float) -> Channel:
        """Wait for the runner to connect, noticing a container that dies first."""
        assert self._listener is not None, "a training container has no protocol socket"
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise ChannelTimeout
            ready, _, _ = select.select([self._listener], [], [], min(left, START_POLL_S))
            if ready:
                break
            if self.exit_status(timeout=0) is not None:
                raise ChannelClosed
        self._connection, _ = self._listener.accept()
        self._listener.close()
        fd = self._connection.fileno()
        return Channel(fd, fd)

    def exit_status(self, timeout: float) -> ExitStatus | None:
        # deferred: the docker client is needed only with the Docker sandbox
        import docker.errors
        import requests.exceptions

        if timeout > 0:
            try:
                self.container.wait(timeout=timeout)
            except (requests.exceptions.ConnectionError, requests.exceptions.ReadTimeout):
                return None
            except docker.errors.NotFound:
                return ExitStatus(None)
        try:
            state = docker_client().api.inspect_container(self.container.id)["State"]
        except docker.errors.NotFound:
            return ExitStatus(None)
        except docker.errors.DockerException as error:
            raise SandboxUnavailable(f"cannot inspect the agent container: {error}") from error
        if state["Running"] and not state["OOMKilled"]:
            return None
        if self._status is None:  # read once: training and resolver loops poll this
            stopped = daemon_stop(self.container.id, self.launched, self._killed_at or time.time())
            self._status = ExitStatus(
                state["ExitCode"], oom_killed=state["OOMKilled"], stopped_by=stopped
            )
        return self._status

    def cpu_meter(self) -> CpuMeter | None:
        """The container's own cgroup, found through its first process."""
        import docker.errors

        try:
            pid = docker_client().api.inspect_container(self.container.id)["State"]["Pid"]
        except docker.errors.DockerException:
            return None
        return cgroup_meter(pid) if pid else None

    def kill(self) -> None:
        # deferred: the docker client is needed only with the Docker sandbox
        import docker.errors
        import requests.exceptions

        if self._killed_at is None:
            self._killed_at = time.time()
        try:
            if self._final_logs is None:
                # The daemon drains the agent's output before it reports the exit, so the log
                # read after the wait is complete.
                with contextlib.suppress(docker.errors.APIError):
                    self.container.kill()
                with contextlib.suppress(requests.exceptions.RequestException):
                    self.container.wait(timeout=KILL_WAIT_S)
                self._final_logs = self.logs()
            self.container.remove(force=True)
        except docker.errors.NotFound:
            pass
        except (docker.errors.DockerException, requests.exceptions.RequestException) as error:
            # Removal already in progress is fine; a daemon gone away is ours to retry.
            if "in progress" not in str(error):
                raise SandboxUnavailable(f"cannot remove the agent container: {error}") from error
        finally:
            for closable in (self._connection, self._listener):
                if closable is not None:
                    closable.close()
            if self._socket_dir is not None:
                shutil.rmtree(self._socket_dir, ignore_errors=True)

    def logs(self) -> str:
        # deferred: the docker client is needed only with the Docker sandbox
        import docker.errors
        import requests.exceptions

        if self._final_logs is not None:
            return self._final_logs
        try:
            data = self.container.logs(stdout=True, stderr=True)
        except docker.errors.NotFound:
            return ""
        except (docker.errors.DockerException, requests.exceptions.RequestException) as error:
            raise SandboxUnavailable(f"cannot read the agent's log: {error}") from error
        return data[-self._log_limit :].decode("utf-8", errors="replace")


class DockerBackend:
    kind = SandboxKind.docker

    def unavailable_reason(self, config: SandboxSettings) -> str | None:
        # deferred: the docker client is needed only with the Docker sandbox
        import docker.errors

        try:
            client = docker_client()
            client.ping()
        except docker.errors.DockerException as error:
            return f"no Docker daemon answers ({error})"
        if missing := missing_image_reason(config.agent_image, "the agent runtime"):
            return missing
        runtime = config.docker_runtime
        if runtime and runtime not in (client.info().get("Runtimes") or {}):
            return (
                f"the Docker daemon has no runtime {runtime!r} (ARENA_DOCKER_RUNTIME): register "
                'it in /etc/docker/daemon.json (docs/sandbox.md, "A stronger tier")'
            )
        return None

    def contract_gap(self, config: SandboxSettings) -> str | None:
        """A container holds every limit of the contract; only the filter needs a table for this
        machine's architecture."""
        return confine.supported()

    def launch(self, spec: LaunchSpec) -> DockerSandbox:
        # deferred: the docker client is needed only with the Docker sandbox
        import docker.errors

        launched = time.time()
        if spec.training is not None:
            try:
                container = docker_client().containers.run(**container_options(spec, None))
            except docker.errors.DockerException as error:
                raise SandboxUnavailable(f"cannot start the training container: {error}") from error
            return DockerSandbox(container, None, None, spec.config.agent_log_tail_bytes, launched)
        socket_dir = socket_dir_for(spec.instance, spec.config.sandbox_shared_dir)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            socket_dir.parent.mkdir(parents=True, exist_ok=True)
            socket_dir.mkdir(mode=0o700)
            path = socket_dir / SOCKET_NAME
            listener.bind(str(path))
            share_with_agent(socket_dir, path)
            listener.listen(1)
            container = docker_client().containers.run(**container_options(spec, socket_dir))
        except (OSError, docker.errors.DockerException) as error:
            listener.close()
            shutil.rmtree(socket_dir, ignore_errors=True)
            raise SandboxUnavailable(f"cannot start the agent container: {error}") from error
        return DockerSandbox(
            container, listener, socket_dir, spec.config.agent_log_tail_bytes, launched
        )

    def cleanup(self, labels: dict[str, str], config: SandboxSettings) -> int:
        # deferred: the docker client is needed only with the Docker sandbox
        import docker.errors
        import requests.exceptions

        selector = [f"{key}={value}" for key, value in labels.items()]
        try:
            client = docker_client()
            containers = client.containers.list(all=True, filters={"label": selector})
            for container in containers:
                with contextlib.suppress(docker.errors.NotFound):
                    container.remove(force=True)
            ours = client.containers.list(all=True, filters={"label": f"{SANDBOX_LABEL}=1"})
        except (docker.errors.DockerException, requests.exceptions.RequestException):
            # No daemon, no containers: cleaning up must not break the other backends' runs.
            return 0
        remove_orphan_socket_dirs(
            {c.labels.get(INSTANCE_LABEL, "") for c in ours}, config.sandbox_shared_dir
        )
        remove_stale_copies(config.sandbox_shared_dir)
        return len(containers)
