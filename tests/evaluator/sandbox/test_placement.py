"""Each job's agent runs on the job's CPUs (``pin_jobs``, evaluator/sandbox/placement.py): shown by
what the agent sees of itself inside its sandbox, on every backend, cold and forked."""

from __future__ import annotations

import multiprocessing
import os

import pytest

from arena.config import Settings
from evaluator.sandbox import start
from evaluator.sandbox.placement import claimed_cpus, job_cpus
from evaluator.sandbox.warm_pool import WarmAgents
from tests.evaluator.sandbox.agents import agent, observation
from tests.settings import sandbox_args, with_fields

# The CPUs the agent may run on, as the scheduler holds them and as the kernel lists them.
REPORTS_CPUS = """
listed = next(line.split(':', 1)[1].strip() for line in open('/proc/self/status')
              if line.startswith('Cpus_allowed_list:'))
return {k: [sorted(os.sched_getaffinity(0)), listed] for k in obs}
"""


def expanded(listed: str) -> list[int]:
    """A kernel CPU list (``0-2,5``) as its CPUs."""
    cpus = []
    for part in listed.split(","):
        first, _, last = part.partition("-")
        cpus += range(int(first), int(last or first) + 1)
    return cpus


def two_cpus() -> tuple[int, int]:
    """The first and last CPU this process may use (skips where there is only one)."""
    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) < 2:
        pytest.skip("one CPU here: every job shares it")
    return allowed[0], allowed[-1]


def seen(handle) -> list[int]:
    """The CPUs the agent behind ``handle`` may run on; the two ways of asking agree."""
    handle.reset()
    affinity, listed = handle.act(observation())["Agent_0"]
    assert affinity == expanded(listed)
    return affinity


def test_jobs_get_cpus_in_turn(settings: Settings) -> None:
    config = settings.sandbox
    assert config.pin_jobs  # the default
    assert [job_cpus(job, config, [0, 1, 2]) for job in range(5)] == [
        (0,),
        (1,),
        (2,),
        (0,),
        (1,),
    ]
    # An agent allowed more than one CPU gets as many (whole CPUs) with its job...
    wide = with_fields(settings, sandbox={"agent_cpus": 1.5}).sandbox
    assert [job_cpus(job, wide, [0, 1, 2, 3, 4]) for job in range(3)] == [(0, 1), (2, 3), (0, 1)]
    # ...and none is pinned where that is every CPU, or where there is nothing to choose.
    assert job_cpus(0, wide, [0, 1]) is None
    assert job_cpus(0, config, [3]) is None
    off = with_fields(settings, sandbox={"pin_jobs": False}).sandbox
    assert job_cpus(1, off, [0, 1, 2]) is None


# CPU numbers no machine here has: their lock files are this test's alone, whatever evaluations
# run beside it.
UNREAL = [9000, 9001, 9002]


def test_a_claimed_cpu_is_not_given_to_another_job(settings: Settings) -> None:
    config = settings.sandbox
    with claimed_cpus(0, config, UNREAL) as first, claimed_cpus(0, config, UNREAL) as second:
        # Another evaluation (or pool process) numbering its jobs from 0 gets the next free CPU.
        assert (first, second) == ((9000,), (9001,))
        with claimed_cpus(2, config, UNREAL) as third, claimed_cpus(1, config, UNREAL) as fourth:
            assert third == (9002,)
            assert fourth is None  # every CPU held: the scheduler places it
    with claimed_cpus(1, config, UNREAL) as again:
        assert again == (9001,)  # released with its block
    off = with_fields(settings, sandbox={"pin_jobs": False}).sandbox
    with claimed_cpus(0, off, UNREAL) as unpinned:
        assert unpinned is None


def _hold_first_cpu(config, held, release) -> None:
    with claimed_cpus(0, config, UNREAL[:2]):
        held.set()
        release.wait(30)


def test_claims_hold_across_processes(settings: Settings) -> None:
    ctx = multiprocessing.get_context("spawn")
    held, release = ctx.Event(), ctx.Event()
    other = ctx.Process(target=_hold_first_cpu, args=(settings.sandbox, held, release))
    other.start()
    try:
        assert held.wait(30)
        with claimed_cpus(0, settings.sandbox, UNREAL[:2]) as cpus:
            assert cpus == (9001,)
    finally:
        release.set()
        other.join(30)
    # A process's claims end with it.
    with claimed_cpus(0, settings.sandbox, UNREAL[:2]) as cpus:
        assert cpus == (9000,)


def test_the_agent_runs_on_its_jobs_cpu(any_kind, settings, labels, tmp) -> None:
    first, last = two_cpus()
    submission = agent(tmp, settings, act=REPORTS_CPUS)
    for cpus in ((last,), (first,), None):
        with start(
            submission, kind=any_kind, labels=labels, cpus=cpus, **sandbox_args(settings)
        ) as handle:
            affinity = seen(handle)
        if cpus is None:  # not pinned: anywhere
            assert len(affinity) > 1
        else:
            assert affinity == list(cpus)


def test_forked_agents_run_on_their_jobs_cpu(any_kind, settings, labels, tmp) -> None:
    """The pool keeps a zygote per CPU set, so each job's episodes fork on the job's CPU."""
    first, last = two_cpus()
    submission = agent(tmp, settings, act=REPORTS_CPUS)
    pool = WarmAgents(labels)
    data_dir = settings.storage.resolved_data_dir
    try:
        for cpus in ((last,), (first,), (last,), None):
            with pool.lease(
                submission, any_kind, labels, settings.sandbox, data_dir, cpus
            ) as forked:
                assert forked is not None
                with forked.start() as handle:
                    affinity = seen(handle)
            if cpus is None:
                assert len(affinity) > 1
            else:
                assert affinity == list(cpus)
    finally:
        pool.close()
