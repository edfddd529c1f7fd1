"""Warm agents: forked per episode from one sandbox, yet isolated as if each had its own.

The hostile cases of ``test_hostile.py`` run again through a forked agent, with the same reasons;
after each the zygote is still alive and nothing of the agent is left.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from arena.config import SandboxKind, Settings
from arena.errors import AgentFailed
from arena.outcome import DoneReason
from evaluator import sandbox
from evaluator.sandbox.warm import WarmAgent
from evaluator.sandbox.warm_pool import WarmAgents
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.conftest import leftovers, usable
from tests.evaluator.sandbox.test_hostile import CASES, FORMATS, Hostile
from tests.settings import sandbox_args, with_fields

# Episode 1 leaves a module global, files in /tmp (one in a folder it made unreadable), a
# System V shared memory segment and a process behind; each episode reports what it found.
LEAVES_TRACES = """
global EPISODES
EPISODES = globals().get('EPISODES', 0) + 1
private = os.getppid() == 1  # the zygote is PID 1 of an isolating sandbox
found_file = os.path.exists('/tmp/note') or os.path.exists('/tmp/locked')
others = 0
for p in os.listdir('/proc'):
    if p.isdigit() and int(p) not in (1, os.getpid()):
        try:
            stat = open(f'/proc/{p}/stat').read()
        except OSError:  # ended since the listing: the process backend sees the host's /proc
            continue
        # This episode's own namespace holder is our child (just forked: it may not have taken
        # its name yet); a process left by an earlier episode would be the zygote's.
        others += int(stat.rsplit(')', 1)[1].split()[1]) != os.getpid()
with open('/proc/sysvipc/shm') as table:
    segments = len(table.readlines()) - 1
if private and EPISODES == 1:
    open('/tmp/note', 'w').write('scenario 1 was here')
    os.makedirs('/tmp/locked/inner')
    os.chmod('/tmp/locked', 0)
    import ctypes
    ctypes.CDLL(None).shmget(0, 4096, 0o1600)  # IPC_PRIVATE, IPC_CREAT | 0600
    if os.fork() == 0:
        os.setsid()
        time.sleep(300)
        os._exit(0)
return {k: [float(EPISODES), float(found_file), float(others), float(segments)]
        for k in obs}
"""


@contextmanager
def zygote(submission, kind: SandboxKind, settings: Settings, labels) -> Iterator[WarmAgent]:
    warm = WarmAgent.start(
        submission, kind, settings.sandbox, settings.storage.resolved_data_dir, labels=labels
    )
    try:
        yield warm
    finally:
        warm.close()
    assert leftovers(kind, labels) == []


def episode(warm: WarmAgent, settings: Settings, steps: int = 1) -> list:
    forked = warm.fork(settings.sandbox, {})
    try:
        with forked.start() as handle:
            handle.reset()
            return [handle.act(observation()) for _ in range(steps)]
    finally:
        forked.close()
        # Generous: under memory pressure on a loaded host the cleanup takes its time.
        assert warm.wait_ready(30.0), "the zygote did not come back clean"


def test_no_state_crosses_from_one_episode_to_the_next(kind, settings, labels, tmp) -> None:
    submission = agent(tmp, settings, act=LEAVES_TRACES)
    with zygote(submission, kind, settings, labels) as warm:
        first = episode(warm, settings, steps=2)
        second = episode(warm, settings)
    # Within an episode the agent keeps its state (2 calls), and sees what it left...
    assert first[0]["Agent_0"] == [1.0, 0.0, 0.0, 0.0]
    assert first[1]["Agent_0"][:2] == [2.0, 1.0]
    # ...but the next episode finds nothing of it: no global, file, process or segment.
    assert second[0]["Agent_0"] == [1.0, 0.0, 0.0, 0.0]


def test_forked_agents_keep_their_state_apart_under_process(settings, labels, tmp) -> None:
    """The unisolated backend forks too; only the module state is fresh (no private /tmp)."""
    submission = agent(tmp, settings, act=LEAVES_TRACES.replace("/proc/sysvipc/shm", "/dev/null"))
    with zygote(submission, SandboxKind.process, settings, labels) as warm:
        assert episode(warm, settings)[0]["Agent_0"][0] == 1.0
        assert episode(warm, settings)[0]["Agent_0"][0] == 1.0


@pytest.mark.parametrize("observation_format", FORMATS)
@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_forked_hostile_agent_fails_with_its_reason(
    case: Hostile, observation_format: str, kind: SandboxKind, settings: Settings, labels, tmp
) -> None:
    run_settings = with_fields(settings, **case.overrides)
    submission = agent(
        tmp,
        run_settings,
        act=case.act,
        init=case.init,
        agent_yaml=f"observation_format: {observation_format}\n",
    )
    with zygote(submission, kind, run_settings, labels) as warm:
        for _ in range(2):  # and again: what the first episode did changes nothing
            with pytest.raises(AgentFailed) as caught:
                episode(warm, run_settings)
            failure = caught.value
            assert failure.reason is case.reason, failure
            if case.evidence:
                assert any(text in failure.detail for text in case.evidence), failure.detail


def test_killing_its_parent_changes_nothing_when_forked(kind, settings, labels, tmp) -> None:
    """The forked agent's parent is the zygote, PID 1 of the sandbox: signals from inside do not
    reach it, and ``kill(-1)`` reaches only the agent's own processes."""
    act = """
    os.kill(os.getppid(), 9)
    try:
        os.kill(-1, 9)
    except ProcessLookupError:
        pass
    return {k: [float(os.getppid()), 0.0] for k in obs}
    """
    submission = agent(tmp, settings, act=act)
    with zygote(submission, kind, settings, labels) as warm:
        assert episode(warm, settings, steps=2) == [{"Agent_0": [1.0, 0.0]}] * 2
        assert episode(warm, settings) == [{"Agent_0": [1.0, 0.0]}]


def test_cleanup_kills_a_leased_agent_and_close_leaves_nothing(kind, settings, labels, tmp) -> None:
    submission = agent(tmp, settings, act="time.sleep(30)")
    slow = with_fields(settings, sandbox={"step_timeout_s": 60.0})
    pool = WarmAgents(labels)
    run = {"arena.run": labels["driving-arena.test"]}
    with pool.lease(submission, kind, run, slow.sandbox, slow.storage.resolved_data_dir) as forked:
        assert forked is not None
        with forked.start() as handle:
            threading.Timer(1.0, pool.kill, args=({**run},)).start()
            started = time.monotonic()
            with pytest.raises(AgentFailed) as caught:
                handle.act(observation())
    assert caught.value.reason is DoneReason.agent_exited
    assert time.monotonic() - started < 10
    pool.close()
    assert leftovers(kind, labels) == []


@pytest.mark.slow
def test_a_zygote_that_cannot_start_means_cold_episodes(settings, labels, tmp) -> None:
    """Nothing of the participant runs in the zygote, so its failure is ours: the pool says
    so with None (the runner then starts that submission's agents cold). Docker only: its
    zygote has an image to break."""
    kind = usable(SandboxKind.docker, settings)
    submission = agent(tmp, settings)
    broken = with_fields(settings, sandbox={"agent_image": "driving-arena-no-such-image:0"})
    pool = WarmAgents(labels)
    with pool.lease(
        submission, kind, {}, broken.sandbox, broken.storage.resolved_data_dir
    ) as forked:
        assert forked is None
    with sandbox.start(
        submission,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        assert handle.act(observation()) == {"Agent_0": [1.0, 0.0]}
