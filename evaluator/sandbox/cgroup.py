"""A control group per sandbox: what caps the memory, processes and CPU share of everything one
bubblewrap sandbox runs, as Docker caps a container's (``docs/sandbox.md``).

Rlimits cannot: ``RLIMIT_AS`` is per process (three children held 1.2 GiB each against a 2 GiB
limit) and ``RLIMIT_NPROC`` counts every process of the host uid, so one sandbox's processes
left another team's unable to fork. A group is made under the evaluating process's own group, in
cgroup v2 when it can delegate ``memory``, ``pids`` and ``cpu`` there, else in the v1
hierarchies of those controllers; the sandbox's first process joins it before it executes
anything, so all it starts is counted.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from arena.errors import SandboxUnavailable

CONTROLLERS = ("memory", "pids", "cpu")
# cgroup v1's CPU time counter, where it is a hierarchy apart from ``cpu``'s: optional (the
# sandbox's meter then walks its process tree, hundreds of microseconds an act instead of one
# read of the group's counter). v2's ``cpu`` controller counts the time itself (cpu.stat).
ACCOUNTING_V1 = "cpuacct"
GROUP_PREFIX = "arena-sandbox-"
CPU_PERIOD_US = 100_000
# A group left by a killed worker is removed once empty and this old; a younger one may be
# waiting for the sandbox being started into it.
ORPHAN_AGE_S = 60.0


class CgroupUnavailable(SandboxUnavailable):
    """No group can be made here for a sandbox (the reason says why)."""


@dataclass(frozen=True)
class Limits:
    memory_bytes: int
    pids: int
    cpus: float


@dataclass(frozen=True)
class Hierarchy:
    """Where this process's groups live: one folder (v2) or one per controller (v1)."""

    version: int
    parents: dict[str, Path]  # controller -> the folder new groups go in

    def folders(self, name: str) -> list[Path]:
        return sorted({parent / name for parent in self.parents.values()})


def _own_groups() -> dict[str, str]:
    """controller (or "" for v2) -> this process's group path, from /proc/self/cgroup."""
    groups = {}
    for line in Path("/proc/self/cgroup").read_text().splitlines():
        _, controllers, path = line.split(":", 2)
        for controller in controllers.split(",") if controllers else [""]:
            groups[controller] = path
    return groups


def _mounts() -> list[tuple[str, Path, str, set[str]]]:
    """(fstype, mount point, root, super options) of every cgroup mount, from mountinfo."""
    found = []
    for line in Path("/proc/self/mountinfo").read_text().splitlines():
        fields = line.split()
        dash = fields.index("-")
        fstype, options = fields[dash + 1], set(fields[dash + 3].split(","))
        if fstype in ("cgroup", "cgroup2"):
            found.append((fstype, Path(fields[4]), fields[3], options))
    return found


def _under(mount: Path, root: str, path: str) -> Path:
    relative = os.path.relpath(path, root) if root != "/" else path.lstrip("/")
    return (mount / relative).resolve() if relative != "." else mount


def _v2(mounts, groups) -> Hierarchy | str:
    for fstype, point, root, _ in mounts:
        if fstype != "cgroup2" or "" not in groups:
            continue
        parent = _under(point, root, groups[""])
        try:
            available = set((parent / "cgroup.controllers").read_text().split())
        except OSError as error:
            return f"cgroup v2 at {parent} is unreadable: {error}"
        missing = [c for c in CONTROLLERS if c not in available]
        if missing:
            return f"cgroup v2 does not delegate {', '.join(missing)} to {parent}"
        try:  # a group of ours may not hold processes and have children with controllers
            (parent / "cgroup.subtree_control").write_text(" ".join(f"+{c}" for c in CONTROLLERS))
        except OSError as error:
            return f"cannot enable {', '.join(CONTROLLERS)} below {parent}: {error.strerror}"
        return Hierarchy(2, {c: parent for c in CONTROLLERS})
    return "no cgroup v2"


def _v1(mounts, groups) -> Hierarchy | str:
    parents = {}
    for controller in CONTROLLERS:
        for fstype, point, root, options in mounts:
            if fstype == "cgroup" and controller in options and controller in groups:
                parents[controller] = _under(point, root, groups[controller])
                break
        else:
            return f"no cgroup v1 {controller} hierarchy"
    for controller, parent in parents.items():
        if not os.access(parent, os.W_OK):
            return f"cannot make groups in {parent} ({controller})"
    for fstype, point, root, options in mounts:
        if fstype == "cgroup" and ACCOUNTING_V1 in options and ACCOUNTING_V1 in groups:
            parent = _under(point, root, groups[ACCOUNTING_V1])
            if os.access(parent, os.W_OK):
                parents[ACCOUNTING_V1] = parent
            break
    return Hierarchy(1, parents)


@lru_cache(maxsize=1)
def hierarchy() -> Hierarchy | str:
    """This process's hierarchy, or why no sandbox group can be made (cached: it probes)."""
    try:
        mounts, groups = _mounts(), _own_groups()
    except OSError as error:
        return f"cannot read this process's cgroups: {error}"
    reasons = []
    for probe in (_v2, _v1):
        found = probe(mounts, groups)
        if isinstance(found, Hierarchy):
            try:
                SandboxGroup.create(found, f"{GROUP_PREFIX}probe-{os.getpid()}", None).remove()
            except (OSError, CgroupUnavailable) as error:
                reasons.append(f"cgroup v{found.version}: {error}")
                continue
            return found
        reasons.append(found)
    return "; ".join(reasons)


def unavailable_reason() -> str | None:
    found = hierarchy()
    return None if isinstance(found, Hierarchy) else found


class SandboxGroup:
    """One sandbox's group (a folder per v1 controller)."""

    def __init__(self, found: Hierarchy, name: str) -> None:
        self.hierarchy = found
        self.folders = found.folders(name)

    @classmethod
    def create(cls, found: Hierarchy, name: str, limits: Limits | None) -> SandboxGroup:
        group = cls(found, name)
        try:
            for folder in group.folders:
                folder.mkdir()
            if limits is not None:
                group._limit(limits)
        except OSError as error:
            group.remove()
            raise CgroupUnavailable(f"cannot make the sandbox's cgroup: {error}") from error
        return group

    @property
    def memory_folder(self) -> Path:
        return self.hierarchy.parents["memory"] / self.folders[0].name

    @property
    def memory_mount(self) -> str:
        """Where a sandbox finds its memory counters, as in a Docker container."""
        return "/sys/fs/cgroup" if self.hierarchy.version == 2 else "/sys/fs/cgroup/memory"

    @property
    def cpu_usage_file(self) -> Path | None:
        """The counter of the CPU time of every process in the group together (cpu.stat or
        cpuacct.usage), or None where v1 has no ``cpuacct`` hierarchy to make the group in."""
        if self.hierarchy.version == 2:
            return self._file("cpu", "cpu.stat")
        if ACCOUNTING_V1 in self.hierarchy.parents:
            return self._file(ACCOUNTING_V1, "cpuacct.usage")
        return None

    def _file(self, controller: str, name: str) -> Path:
        return self.hierarchy.parents[controller].joinpath(self.folders[0].name, name)

    def _limit(self, limits: Limits) -> None:
        quota = max(int(limits.cpus * CPU_PERIOD_US), 1000)
        if self.hierarchy.version == 2:
            self._file("memory", "memory.max").write_text(str(limits.memory_bytes))
            with contextlib.suppress(FileNotFoundError):  # no swap accounting: no swap to cap
                self._file("memory", "memory.swap.max").write_text("0")
            self._file("pids", "pids.max").write_text(str(limits.pids))
            self._file("cpu", "cpu.max").write_text(f"{quota} {CPU_PERIOD_US}")
            return
        self._file("memory", "memory.limit_in_bytes").write_text(str(limits.memory_bytes))
        with contextlib.suppress(FileNotFoundError):
            self._file("memory", "memory.memsw.limit_in_bytes").write_text(str(limits.memory_bytes))
        self._file("pids", "pids.max").write_text(str(limits.pids))
        self._file("cpu", "cpu.cfs_period_us").write_text(str(CPU_PERIOD_US))
        self._file("cpu", "cpu.cfs_quota_us").write_text(str(quota))

    def join(self) -> None:
        """Move the calling process into the group (a ``preexec_fn``: before it runs anything)."""
        pid = str(os.getpid())
        for folder in self.folders:
            (folder / "cgroup.procs").write_text(pid)

    def pids(self) -> set[int]:
        found = set()
        for folder in self.folders:
            with contextlib.suppress(OSError, ValueError):
                found |= {int(p) for p in (folder / "cgroup.procs").read_text().split()}
        return found

    def oom_kills(self) -> int:
        """How many of its processes the kernel killed for the group's memory limit."""
        name = "memory.events" if self.hierarchy.version == 2 else "memory.oom_control"
        with contextlib.suppress(OSError, ValueError):
            for line in self._file("memory", name).read_text().splitlines():
                key, _, value = line.partition(" ")
                if key == "oom_kill":
                    return int(value)
        return 0

    def kill(self, wait_s: float = 5.0) -> None:
        """SIGKILL every process in it until none is left (a fork in flight joins the group)."""
        deadline = time.monotonic() + wait_s
        while (pids := self.pids()) and time.monotonic() < deadline:
            for pid in pids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            time.sleep(0.005)

    def remove(self) -> None:
        """Kill what is left and delete the group's folders."""
        self.kill()
        for folder in self.folders:
            for _ in range(200):  # the last processes leave the group as they are reaped
                try:
                    folder.rmdir()
                    break
                except FileNotFoundError:
                    break
                except OSError:
                    time.sleep(0.01)


def remove_orphans() -> None:
    """Delete the empty groups of sandboxes whose worker died (never a live one: those are
    not empty, and the kernel refuses to remove them)."""
    found = hierarchy()
    if not isinstance(found, Hierarchy):
        return
    cutoff = time.time() - ORPHAN_AGE_S
    for parent in set(found.parents.values()):
        for folder in parent.glob(f"{GROUP_PREFIX}*"):
            with contextlib.suppress(OSError):
                if folder.stat().st_mtime < cutoff:
                    folder.rmdir()
