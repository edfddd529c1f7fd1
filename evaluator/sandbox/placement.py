"""Which CPUs an evaluation job runs on: its simulator and its agent together (``pin_jobs``).

Every simulation step is a strict hand-off: the simulator sends the observation and waits, the
agent computes, answers and waits. When the two processes sit on different CPUs each hand-off
wakes the other, idle, core, which on a virtual machine costs tens of microseconds (measured:
a socket ping-pong between two processes took 64 to 80 us on a 2-core KVM guest, 17 us with both
on one CPU), twice a step; on one CPU it is a context switch. So each job of an evaluation gets
CPUs of its own, held host-wide while it runs (:func:`claimed_cpus`): the process that simulates
its episodes pins itself there (:func:`pin_process`, called by the episode's agent factory,
``evaluator.runner.scenario``), and the job's sandbox is made there: Docker's ``cpuset_cpus``,
the affinity of the first process of bubblewrap's and the process runner's sandboxes (all they
start inherit it), and the zygote of a warm agent, which the pool keeps per CPU set
(:mod:`evaluator.sandbox.warm_pool`).

What does not change: the agent's CPU quota (``agent_cpus``) and its limits, which count its own
CPU time (``evaluator.sandbox.handle``): the simulator it shares the CPU with is blocked on the
agent's answer while the agent computes, so an act's CPU time, and the verdicts, are the same.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import math
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from arena.config import SandboxSettings


def job_cpus(
    job: int, config: SandboxSettings, allowed: Iterable[int] | None = None
) -> tuple[int, ...] | None:
    """The CPUs job ``job`` (0, 1, ...) of an evaluation prefers, from ``allowed`` (default:
    this process's): one, or ``ceil(agent_cpus)`` when the agent may use more than one, taken in
    turn (round robin when jobs exceed CPUs). None: not pinned, when the setting is off or the
    agent's share needs every CPU there is."""
    groups = _cpu_groups(config, allowed)
    return groups[job % len(groups)] if groups else None


@contextlib.contextmanager
def claimed_cpus(
    job: int, config: SandboxSettings, allowed: Iterable[int] | None = None
) -> Iterator[tuple[int, ...] | None]:
    """The CPUs of job ``job`` for as long as the block runs: its own (:func:`job_cpus`) if no
    other job on this machine holds them, else the first CPUs no job holds, else None (not
    pinned: the scheduler places it). Held host-wide (a lock file a CPU, released when the block
    ends or its process dies): two evaluations, two service workers or a worker's pool processes
    each number their jobs from 0, and must not all pile onto the first CPU."""
    groups = _cpu_groups(config, allowed)
    if not groups:
        yield None
        return
    start = job % len(groups)
    with contextlib.ExitStack() as held:
        for group in groups[start:] + groups[:start]:
            if _hold(group, held):
                yield group
                return
        yield None


def _cpu_groups(config: SandboxSettings, allowed: Iterable[int] | None) -> list[tuple[int, ...]]:
    if not config.pin_jobs:
        return []
    cpus = sorted(os.sched_getaffinity(0) if allowed is None else allowed)
    width = max(1, math.ceil(config.agent_cpus))
    if width >= len(cpus):
        return []
    return [tuple(cpus[i * width : (i + 1) * width]) for i in range(len(cpus) // width)]


def _hold(cpus: tuple[int, ...], held: contextlib.ExitStack) -> bool:
    """Lock every CPU of ``cpus`` (all or none: on a miss the ones taken are let go)."""
    with contextlib.ExitStack() as taking:
        for cpu in cpus:
            lock = _lock_file(cpu)
            if lock is None:
                return False
            taking.callback(os.close, lock)
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return False
        held.push(taking.pop_all())
        return True


def _lock_file(cpu: int) -> int | None:
    """A descriptor of CPU ``cpu``'s lock file (None where this user cannot make or open it:
    the job runs unpinned). One open each: flock excludes separate opens in one process too."""
    folder = Path(tempfile.gettempdir()) / "driving-arena-cpus"
    try:
        folder.mkdir(mode=0o1777, exist_ok=True)
        # Read-only is enough to flock, so a file another user made serves as well.
        return os.open(folder / f"cpu{cpu}.lock", os.O_RDONLY | os.O_CREAT, 0o644)
    except OSError:
        return None


@functools.cache
def _unpinned() -> frozenset[int]:
    """This process's CPUs before it was first pinned (read at the first :func:`pin_process`;
    inherited by its children with the cache)."""
    return frozenset(os.sched_getaffinity(0))


def pin_process(cpus: tuple[int, ...] | None) -> None:
    """Run every thread of this process (and what it starts from now on) on ``cpus``; None:
    back on the CPUs it had before it was first pinned. An episode process serves episodes of
    several jobs in turn, so each episode places it again."""
    before = _unpinned()
    target = set(cpus) if cpus is not None else set(before)
    # The affinity is each thread's own: the threads already running move too.
    for task in os.listdir("/proc/self/task"):
        with contextlib.suppress(ProcessLookupError):  # a thread that ended meanwhile
            os.sched_setaffinity(int(task), target)


def cpuset(cpus: tuple[int, ...]) -> str:
    """``cpus`` as a cpuset list (Docker's ``cpuset_cpus``)."""
    return ",".join(str(cpu) for cpu in cpus)
