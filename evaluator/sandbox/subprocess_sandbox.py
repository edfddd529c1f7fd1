"""A sandbox that is a local child process (bubblewrap or a plain runner), talking over pipes."""

from __future__ import annotations

import contextlib
import math
import os
import resource
import shutil
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

from evaluator.sandbox.backend import ExitStatus
from evaluator.sandbox.cgroup import SandboxGroup
from evaluator.sandbox.channel import Channel
from evaluator.sandbox.cpu import CpuMeter

# Children carry their labels in this variable; cleanup finds them through /proc/<pid>/environ.
LABELS_ENV = "DRIVING_ARENA_SANDBOX_LABELS"


def encode_labels(labels: dict[str, str]) -> str:
    return ";".join(f"{key}={value}" for key, value in sorted(labels.items()))


class LogTail:
    """Drains a pipe on a thread, keeping only its last ``limit`` bytes."""

    def __init__(self, pipe, limit: int) -> None:
        self._pipe = pipe
        self._limit = limit
        self._data = bytearray()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._drain, name="agent-stderr", daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        fd = self._pipe.fileno()
        while chunk := os.read(fd, 256 * 1024):
            with self._lock:
                self._data += chunk
                if len(self._data) > 2 * self._limit:
                    del self._data[: -self._limit]

    def text(self, wait: float = 0.0) -> str:
        self._thread.join(wait)
        with self._lock:
            return bytes(self._data[-self._limit :]).decode("utf-8", errors="replace")


def rlimit_setter(
    memory_bytes: int | None,
    processes: int | None,
    cpu_seconds: float | None = None,
    file_bytes: int | None = None,
    cpus: tuple[int, ...] | None = None,
) -> Callable[[], None]:
    """A preexec function that caps core dumps and, when given, address space, processes, CPU
    time and file size: per process, so only where no control group caps the whole sandbox.
    With ``cpus`` it also puts the sandbox's first process, and so all it starts, on those CPUs
    (its job's, :mod:`evaluator.sandbox.placement`).

    Without cgroups there is no CPU share to cap, so the CPU time an agent may burn is bounded
    instead: start-up's CPU limit plus one episode's wall time on one CPU (SIGXCPU, then SIGKILL
    5 s later).
    """

    def apply() -> None:
        if cpus is not None:
            os.sched_setaffinity(0, cpus)
        if memory_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        if file_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_bytes, file_bytes))
        if cpu_seconds is not None:
            soft = math.ceil(cpu_seconds)
            resource.setrlimit(resource.RLIMIT_CPU, (soft, soft + 5))
        if processes is not None:
            resource.setrlimit(resource.RLIMIT_NPROC, (processes, processes))

    return apply


def control_pair(spec_zygote: bool) -> tuple[socket.socket | None, int | None]:
    """(our end, the child's stdin and stdout) of a unix socket for a warm parent, which receives
    descriptors on it; (None, None) for an agent, which talks over pipes."""
    if not spec_zygote:
        return None, None
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    return ours, theirs.detach()


def sandbox_streams(training: bool, control_end: int | None) -> dict[str, int]:
    """Popen's stdin, stdout and stderr: a training run talks to no one (its output is its log),
    a warm parent talks over its control socket, an agent over pipes (stderr is its log)."""
    if training:
        return {"stdin": subprocess.DEVNULL, "stdout": subprocess.PIPE, "stderr": subprocess.STDOUT}
    protocol = control_end if control_end is not None else subprocess.PIPE
    return {"stdin": protocol, "stdout": protocol, "stderr": subprocess.PIPE}


class PopenSandbox:
    def __init__(
        self,
        process: subprocess.Popen,
        log_limit: int,
        labels: dict[str, str],
        cleanup: Path | None = None,
        control: socket.socket | None = None,
        group: SandboxGroup | None = None,
    ) -> None:
        self.process = process
        # An agent's log is its stderr (stdout carries the protocol); a training run's is both.
        self._log_pipe = process.stderr or process.stdout
        self._stderr = LogTail(self._log_pipe, log_limit)
        self._labels = labels
        self._cleanup = cleanup  # a folder of ours to delete once the sandbox is gone
        self.control = control  # a warm parent's socket (stdin and stdout), else pipes
        self._group = group  # its control group, removed with it

    def connect(self, deadline: float) -> Channel:
        if self.control is not None:
            return Channel(self.control.fileno(), self.control.fileno())
        return Channel(self.process.stdout.fileno(), self.process.stdin.fileno())

    def exit_status(self, timeout: float) -> ExitStatus | None:
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            return None
        oom = self._group is not None and self._group.oom_kills() > 0
        return ExitStatus(code, oom_killed=oom)

    def kill(self) -> None:
        if self.process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()
        # What the agent forked inside its own session or pid namespace dies with the sandbox's
        # init a moment later; wait for that too, so nothing outlives kill().
        kill_labelled(self._labels)
        if self._group is not None:
            self._group.remove()
        for stream in (self.process.stdin, self.process.stdout, self.control):
            if stream is not None and stream is not self._log_pipe:
                with contextlib.suppress(OSError):
                    stream.close()
        self._stderr.text(wait=1.0)
        self._log_pipe.close()
        if self._cleanup is not None:
            shutil.rmtree(self._cleanup, ignore_errors=True)

    def logs(self) -> str:
        return self._stderr.text(wait=0.0 if self.process.poll() is None else 0.5)

    def cpu_meter(self) -> CpuMeter:
        """The counter of the sandbox's cgroup (bubblewrap), read in place at every act; else
        the process tree under its root (the process runner, which has no group)."""
        usage = self._group.cpu_usage_file if self._group is not None else None
        if usage is not None:
            return CpuMeter(cgroup_file=str(usage))
        return CpuMeter(root_pid=self.process.pid)


def labelled_pids(labels: dict[str, str]) -> list[int]:
    """Live (not zombie) processes whose environment carries all ``labels``."""
    wanted = {f"{key}={value}" for key, value in labels.items()}
    prefix = f"{LABELS_ENV}=".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        for variable in environ:
            if variable.startswith(prefix):
                carried = set(variable[len(prefix) :].decode(errors="replace").split(";"))
                if wanted <= carried and is_alive(int(entry.name)):
                    found.append(int(entry.name))
                break
    return found


def is_alive(pid: int) -> bool:
    """True unless the process is gone or a zombie (dead, holding nothing but its pid)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


def kill_labelled(labels: dict[str, str], wait_s: float = 5.0) -> int:
    """SIGKILL the labelled processes and wait until they are dead."""
    pids = labelled_pids(labels)
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + wait_s
    while any(is_alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.01)
    return len(pids)
