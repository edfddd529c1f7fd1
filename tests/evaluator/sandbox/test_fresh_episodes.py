"""Several episodes in one warm sandbox are as independent as episodes in different sandboxes: a
probe agent leaves marks in every kind of writable state it can reach (files in /tmp, /dev/shm,
/dev, /dev/mqueue and home, System V and POSIX IPC, an abstract unix socket, a keyring, its
environment, a process, the cgroup's memory peak, the hostname) and the next episodes find none.

On the old zygote, which scanned and cleaned, an agent that set /tmp to mode 000 made the scan
answer "clean" and the next episode read the notes left there.
"""

from __future__ import annotations

from pathlib import Path

from tests.evaluator.sandbox.agents import agent
from tests.evaluator.sandbox.probe_policy import KINDS
from tests.evaluator.sandbox.test_warm import episode, zygote
from tests.settings import with_fields

PROBE = Path(__file__).with_name("probe_policy.py")
EPISODES = 3


def found(answer: list[dict]) -> set[str]:
    return {kind for kind, mark in zip(KINDS, answer["Agent_0"], strict=True) if mark}


def test_no_mark_of_an_episode_reaches_the_next(kind, settings, labels, tmp) -> None:
    submission = agent(tmp, settings, source=PROBE.read_text())
    roomy = with_fields(settings, sandbox={"step_timeout_s": 10.0})
    with zygote(submission, kind, roomy, labels) as warm:
        episodes = [episode(warm, roomy, steps=2) for _ in range(EPISODES)]
    for index, (before, after) in enumerate(episodes):
        assert found(before) == set(), f"episode {index} found marks of an earlier one"
        # Within the episode the probes do see what it left where it could write.
        seen = {"tmp file", "home file", "sysv shm", "abstract socket", "process", "environment"}
        assert seen <= found(after), found(after)
    # What no agent may write at all.
    assert not {"dev file", "keyring", "hostname"} & found(episodes[0][1])
