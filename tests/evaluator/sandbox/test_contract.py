"""The sandbox contract (docs/sandbox.md), checked from inside a real sandbox of every backend the
service accepts: limits hold for the whole sandbox (not per process, not per host uid), /dev is
not writable, the seccomp filter refuses keyrings and new namespaces.

Each case is a reproduction of a hole the bubblewrap backend had when it capped memory and
processes with rlimits and left /dev writable with no filter.
"""

from __future__ import annotations

import threading

import pytest

from arena.errors import AgentFailed
from evaluator.sandbox import check_service_kind, start
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.conftest import assert_clean_and_healthy
from tests.evaluator.sandbox.test_warm import episode, zygote
from tests.settings import sandbox_args, with_fields

MiB = 1024**2


def answer(
    kind, settings, labels, tmp, act: str, init: str = "pass", warm: bool = False
) -> list[float]:
    """The agent's first action: in a sandbox of its own, or (``warm``) forked in a warm one
    for its second episode (the first ran the same code, so nothing is new to the sandbox)."""
    submission = agent(tmp, settings, act=act, init=init)
    # These acts burn CPU on purpose: the per-step CPU limit is not what they probe.
    settings = with_fields(
        settings,
        sandbox={
            "step_timeout_s": max(settings.sandbox.step_timeout_s, 10.0),
            "step_cpu_s": max(settings.sandbox.step_cpu_s, 10.0),
        },
    )
    if warm:
        with zygote(submission, kind, settings, labels) as parent:
            episode(parent, settings)
            return episode(parent, settings)[0]["Agent_0"]
    with start(
        submission,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        return handle.act(observation())["Agent_0"]


@pytest.fixture(params=[False, True], ids=["cold", "warm"])
def warm(request) -> bool:
    return request.param


def test_every_isolating_backend_here_is_one_the_service_accepts(kind, settings) -> None:
    """The tests below run over the backends this machine offers; each must meet the contract,
    or the service would refuse it (and then it is no sandbox of the service's to test)."""
    assert check_service_kind(kind, settings.sandbox) is kind


def test_memory_is_capped_for_all_processes_together(kind, warm, settings, labels, tmp, good_agent):
    """Three children holding 300 MiB each against 512 MiB: not all three survive (under
    per-process RLIMIT_AS each child had the whole limit to itself)."""
    small = with_fields(settings, sandbox={"agent_memory_bytes": 512 * MiB})
    act = """
    children = []
    for _ in range(3):
        reader, writer = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                ballast = np.ones(300 * 1024**2, dtype=np.uint8)
                os.write(writer, b'1')
                time.sleep(60)
            finally:
                os._exit(0)
        os.close(writer)
        children.append((pid, reader))
    holding = 0
    for pid, reader in children:
        holding += os.read(reader, 1) == b'1'
    time.sleep(0.5)
    alive = sum(os.waitpid(pid, os.WNOHANG) == (0, 0) for pid, _ in children)
    return {k: [float(holding), float(alive)] for k in obs}
    """
    try:
        holding, alive = answer(kind, small, labels, tmp, act, warm=warm)
    except AgentFailed as failure:  # the OOM killer may pick the agent itself
        assert failure.reason.value in ("memory_limit", "agent_exited"), failure
    else:
        assert alive < 3 and holding <= 3, (holding, alive)
    assert_clean_and_healthy(kind, labels, settings, good_agent)


def test_process_limit_is_per_sandbox_not_per_host_uid(kind, settings, labels, tmp, good_agent):
    """One sandbox holding 50 processes leaves another (another team's) free to fork 20."""
    hog = agent(
        tmp / "hog",
        settings,
        act="""
        for _ in range(50):
            if os.fork() == 0:
                time.sleep(120)
                os._exit(0)
        return {k: [1.0, 0.0] for k in obs}
        """,
    )
    forker = """
    made = 0
    for _ in range(20):
        try:
            pid = os.fork()
        except OSError:
            break
        if pid == 0:
            time.sleep(5)
            os._exit(0)
        made += 1
    return {k: [float(made), 0.0] for k in obs}
    """
    with start(
        hog,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        handle.act(observation())
        made, _ = answer(kind, settings, labels, tmp / "other", forker)
    assert made == 20
    assert_clean_and_healthy(kind, labels, settings, good_agent)


def test_cpu_share_is_capped_for_the_whole_sandbox(kind, settings, labels, tmp) -> None:
    """Two processes spinning for 2 s burn at most ``agent_cpus`` x 2 s of CPU together."""
    act = """
    import resource
    began = time.monotonic()
    pids = []
    for _ in range(2):
        pid = os.fork()
        if pid == 0:
            while time.monotonic() - began < 2.0:
                pass
            os._exit(0)
        pids.append(pid)
    for pid in pids:
        os.waitpid(pid, 0)
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {k: [used.ru_utime + used.ru_stime, time.monotonic() - began] for k in obs}
    """
    cpu_s, wall_s = answer(kind, settings, labels, tmp, act)
    assert cpu_s <= settings.sandbox.agent_cpus * wall_s * 1.15 + 0.2, (cpu_s, wall_s)


def test_dev_is_not_writable_and_shm_is_bounded(kind, warm, settings, labels, tmp) -> None:
    """/dev was a writable tmpfs with no size limit under bubblewrap (2.5 GiB of host RAM)."""
    act = """
    try:
        open('/dev/mark', 'w').write('x')
        dev = 1.0
    except OSError:
        dev = 0.0
    written = 0
    if os.path.isdir('/dev/shm'):
        try:
            with open('/dev/shm/fill', 'wb') as fill:
                for _ in range(1024):
                    fill.write(b'x' * 1024**2)
                    fill.flush()
                    written += 1
        except OSError:
            pass
    return {k: [dev, float(written)] for k in obs}
    """
    dev, written_mib = answer(kind, settings, labels, tmp, act, warm=warm)
    assert dev == 0.0
    assert written_mib * MiB <= settings.sandbox.agent_tmp_bytes


SYSCALL_PROBE = """
import ctypes
libc = ctypes.CDLL(None, use_errno=True)
def refused(call, *args):
    result = call(*args)
    return float(result == -1 and ctypes.get_errno() in (1, 13, 38))
keyring = refused(libc.syscall, 248, b'user', b'arena-mark', b'x', 1, -3)  # add_key, user keyring
keyctl = refused(libc.syscall, 250, 0, -3, 0)  # keyctl(GET_KEYRING_ID, user)
userns = refused(libc.unshare, 0x10000000)  # CLONE_NEWUSER
mount = refused(libc.mount, b'tmpfs', b'/tmp', b'tmpfs', 0, None)
filtered = float('Seccomp:\\t2' in open('/proc/self/status').read())
return {k: [keyring, keyctl, userns, mount, filtered] for k in obs}
"""


def test_seccomp_refuses_keyrings_and_new_namespaces(kind, warm, settings, labels, tmp) -> None:
    assert answer(kind, settings, labels, tmp, SYSCALL_PROBE, warm=warm) == [1.0] * 5


def test_a_sandbox_too_big_to_start_is_the_agents(kind, settings, labels, tmp) -> None:
    """Sanity of the memory cap at start: a policy allocating beyond it is charged."""
    small = with_fields(settings, sandbox={"agent_memory_bytes": 256 * MiB})
    with pytest.raises(AgentFailed) as caught:
        answer(kind, small, labels, tmp, "return {}", init="self.b = np.ones(400 * 1024**2)")
    assert caught.value.reason.value in ("memory_limit", "agent_error", "agent_exited")


def test_two_sandboxes_fork_at_once_without_starving_each_other(kind, settings, labels, tmp):
    """Concurrent sandboxes of the same host uid each get their own pids budget."""
    results: list[float] = []
    act = """
    pids = []
    for _ in range(40):
        pid = os.fork()
        if pid == 0:
            time.sleep(3)
            os._exit(0)
        pids.append(pid)
    return {k: [float(len(pids)), 0.0] for k in obs}
    """

    def run(index: int) -> None:
        results.append(answer(kind, settings, labels, tmp / f"s{index}", act)[0])

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert results == [40.0, 40.0]
