"""Loading the policy and each ``reset`` are limited by the agent's CPU time (``init_cpu_s``), as
an act is, with the wall clock only as the backstop (``init_timeout_s``): an agent that waits
while it starts (a busy worker, a slow disk, a sleep) is not charged ``init_timeout``, one that
computes too long or never answers is, and the detail says which limit it passed."""

from __future__ import annotations

import pytest

from arena.errors import AgentFailed
from arena.outcome import DoneReason
from tests.evaluator.sandbox.agents import agent, handle_of, observation
from tests.settings import with_fields

# The limits of these tests: half a second of CPU (loading this policy takes a few ms of it),
# ten of wall time.
SMALL = {"init_cpu_s": 0.5, "init_timeout_s": 10.0}
# A wall backstop passed quickly, still long enough for the runtime's own start (before hello).
SHORT_WALL = {"init_cpu_s": 0.5, "init_timeout_s": 4.0}

WAITS = "time.sleep(1.2)"  # over twice the CPU limit of waiting, an eighth of the backstop
SPINS = "while True:\n    pass"  # CPU past any limit, never answering
SLEEPS = "time.sleep(60)"  # past the backstop, using no CPU


def policy(init: str = "pass", reset: str = "pass") -> str:
    """A policy.py that runs ``init`` in ``__init__`` and ``reset`` in its reset hook."""

    def body(code: str) -> str:
        return "\n".join(" " * 8 + line for line in code.splitlines())

    return (
        "import time\n\n"
        "class Policy:\n"
        "    def __init__(self):\n"
        f"{body(init)}\n"
        "    def reset(self):\n"
        f"{body(reset)}\n"
        "    def act(self, obs):\n"
        "        return {k: [1.0, 0.0] for k in obs}\n"
    )


# The fast tier keeps a cold start of each kind; a warm one and a reset go with the slow tests.
COLD_OR_WARM = pytest.mark.parametrize(
    "warm", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["cold", "warm"]
)
RESET = pytest.mark.slow


@COLD_OR_WARM
@pytest.mark.parametrize("phase", ["init", pytest.param("reset", marks=RESET)])
def test_waiting_while_starting_is_not_charged(phase, warm, any_kind, settings, labels, tmp):
    """Over a second of waiting in ``__init__`` or ``reset`` passes a 0.5 s CPU limit: the
    agent starts, resets and acts."""
    limits = with_fields(settings, sandbox=SMALL)
    submission = agent(tmp, limits, source=policy(**{phase: WAITS}))
    with handle_of(submission, any_kind, limits, labels, warm) as handle:
        handle.reset()
        assert handle.act(observation()) == {"Agent_0": [1.0, 0.0]}


@COLD_OR_WARM
@pytest.mark.parametrize(
    ("phase", "doing"),
    [
        ("init", "importing and building the policy"),
        pytest.param("reset", "the policy's reset", marks=RESET),
    ],
)
def test_computing_past_the_cpu_limit_is_init_timeout(
    phase, doing, warm, any_kind, settings, labels, tmp
):
    """A spin in ``__init__`` or ``reset`` is stopped by its CPU time, long before the wall
    clock's backstop, and the detail names the CPU limit."""
    limits = with_fields(settings, sandbox=SMALL)
    submission = agent(tmp, limits, source=policy(**{phase: SPINS}))
    with (
        pytest.raises(AgentFailed) as caught,
        handle_of(submission, any_kind, limits, labels, warm) as handle,
    ):
        handle.reset()
    assert caught.value.reason is DoneReason.init_timeout
    assert f"{doing} used more than 0.5 s of CPU" in caught.value.detail, caught.value.detail
    assert caught.value.cpu_s > 0.5


@pytest.mark.slow  # seconds of sleeping, on every backend
@pytest.mark.parametrize(("phase", "kind_of_answer"), [("init", "ready"), ("reset", "done")])
def test_waiting_past_the_wall_backstop_is_init_timeout(
    phase, kind_of_answer, any_kind, settings, labels, tmp
):
    """A sleep past ``init_timeout_s`` uses no CPU but is stopped by the wall clock, and the
    detail names the wall time."""
    limits = with_fields(settings, sandbox=SHORT_WALL)
    submission = agent(tmp, limits, source=policy(**{phase: SLEEPS}))
    with (
        pytest.raises(AgentFailed) as caught,
        handle_of(submission, any_kind, limits, labels, warm=False) as handle,
    ):
        handle.reset()
    assert caught.value.reason is DoneReason.init_timeout
    assert caught.value.detail == f"no {kind_of_answer} within 4 s of wall time"
