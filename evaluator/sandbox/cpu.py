"""The CPU time a sandbox has used, read from the host (never asked of the agent, which could lie).

A step's limit counts the agent's CPU time, not the wall clock, so a score does not depend on how
busy the worker was (``docs/protocol.md``, "Time limits"). Two ways to read it:

- a **cgroup** of the sandbox's own (Docker, and bubblewrap's :mod:`evaluator.sandbox.cgroup`):
  ``cpu.stat``'s ``usage_usec`` (cgroup v2) or ``cpuacct.usage`` (v1), every process of the
  sandbox together;
- a **process tree** (the plain process runner, and bubblewrap where v1 has no ``cpuacct``):
  the CPU time of the sandbox's root process and every live descendant, plus what its ended
  children left in their parents' ``cutime``/``cstime``. A live process counts its threads'
  ``schedstat`` run time (nanoseconds): ``stat``'s ``utime``/``stime`` come in clock ticks
  (10 ms), which would read a cheap agent's whole episode as zero. ``stat`` still counts where it
  says more, since it keeps the time of threads that have ended.

A :class:`CpuMeter` is a plain description (a file or a pid), so it travels with a forked agent
into the episode process. A warm sandbox's meter counts its idle zygote too, which uses nothing
while an episode runs.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

CGROUP_ROOT = Path("/sys/fs/cgroup")
_TICKS = os.sysconf("SC_CLK_TCK")


@dataclass(frozen=True)
class CpuMeter:
    cgroup_file: str | None = None  # cpu.stat (v2) or cpuacct.usage (v1)
    root_pid: int | None = None

    def seconds(self) -> float | None:
        """CPU seconds used so far; None when it can no longer be read (the sandbox ended)."""
        try:
            if self.cgroup_file is not None:
                return _cgroup_seconds(self.cgroup_file)
            if self.root_pid is not None:
                return _tree_seconds(self.root_pid)
        except (OSError, ValueError, IndexError):
            return None
        return None

    def open(self) -> CpuReader:
        """A reader for reading this meter on every act: it keeps a cgroup file open."""
        return CpuReader(self)


class CpuReader:
    """:meth:`CpuMeter.seconds` for many reads, closed after the last. A cgroup file is opened
    once and read again in place: about 1.5 µs a read instead of 23 µs opening it each time (an
    act reads the meter once). Its readings never go down: a process tree's can, by up to a clock
    tick, when a thread ends and its nanoseconds give way to ``stat``'s ticks."""

    def __init__(self, meter: CpuMeter) -> None:
        self._meter = meter
        self._highest = 0.0
        self._fd: int | None = None
        if meter.cgroup_file is not None:
            # Unopenable: read as the meter would, which answers None.
            with contextlib.suppress(OSError):
                self._fd = os.open(meter.cgroup_file, os.O_RDONLY | os.O_CLOEXEC)

    def seconds(self) -> float | None:
        reading = self._read()
        if reading is None:
            return None
        self._highest = max(self._highest, reading)
        return self._highest

    def _read(self) -> float | None:
        if self._fd is None:
            return self._meter.seconds()
        try:
            return _cgroup_usage(self._meter.cgroup_file, os.pread(self._fd, 4096, 0).decode())
        except (OSError, ValueError, IndexError):
            return None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def cgroup_meter(pid: int) -> CpuMeter | None:
    """The meter of the cgroup ``pid`` runs in, or None when it runs in the root cgroup or has
    no CPU accounting file."""
    try:
        lines = Path(f"/proc/{pid}/cgroup").read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        _, controllers, path = line.split(":", 2)
        relative = path.lstrip("/")
        if not relative:
            continue  # the root cgroup is the whole machine, not the sandbox
        if controllers == "":  # cgroup v2
            candidate = CGROUP_ROOT / relative / "cpu.stat"
        elif "cpuacct" in controllers.split(","):
            candidate = CGROUP_ROOT / controllers / relative / "cpuacct.usage"
            if not candidate.exists():
                candidate = CGROUP_ROOT / "cpu,cpuacct" / relative / "cpuacct.usage"
        else:
            continue
        if candidate.is_file():
            return CpuMeter(cgroup_file=str(candidate))
    return None


def _cgroup_seconds(path: str) -> float:
    return _cgroup_usage(path, Path(path).read_text())


def _cgroup_usage(path: str, text: str) -> float:
    """CPU seconds in ``text``, the contents of the cgroup file ``path``."""
    if path.endswith("cpuacct.usage"):
        return int(text) / 1e9
    for line in text.splitlines():
        name, _, value = line.partition(" ")
        if name == "usage_usec":
            return int(value) / 1e6
    raise ValueError(f"no usage_usec in {path}")


def _tree_seconds(root: int) -> float:
    seconds = 0.0
    pending = [root]
    seen = set()
    while pending:
        pid = pending.pop()
        if pid in seen:
            continue
        seen.add(pid)
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            if pid == root:
                raise
            continue  # ended between the listing and now: its time is in its parent's cutime
        fields = stat.rsplit(")", 1)[1].split()
        # utime, stime, cutime, cstime are fields 14-17 of stat; 2 (comm) is cut off above.
        own_ticks, ended_children_ticks = (
            int(fields[11]) + int(fields[12]),
            int(fields[13]) + int(fields[14]),
        )
        run_ns = 0
        for task in _tasks(pid):
            task_dir = f"/proc/{pid}/task/{task}"
            with contextlib.suppress(OSError):  # the thread ended: its time is in stat's
                run_ns += int(Path(f"{task_dir}/schedstat").read_text().split()[0])
            with contextlib.suppress(OSError):
                pending.extend(int(c) for c in Path(f"{task_dir}/children").read_text().split())
        seconds += max(run_ns / 1e9, own_ticks / _TICKS) + ended_children_ticks / _TICKS
    return seconds


def _tasks(pid: int) -> list[str]:
    try:
        return os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []
