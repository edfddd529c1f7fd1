"""Issue 40: an episode's CPU is the team's from the moment its code is loaded: ``__init__`` and
``reset`` count towards the episode's budget (and the evaluation's) as acts do, and an agent that
fails to start still carries what it used. Every isolating backend, cold and forked warm."""

from __future__ import annotations

import pytest

from arena.errors import AgentFailed
from arena.outcome import DoneReason
from tests.evaluator.sandbox.agents import agent, handle_of, observation
from tests.settings import with_fields

BURN = """
def burn(seconds):
    began = time.process_time()
    while time.process_time() - began < seconds:
        pass
"""

HEAVY_LOAD = f"""import time
{BURN}
burn(0.6)  # at import of policy.py

class Policy:
    def __init__(self):
        burn(0.6)

    def reset(self):
        burn(0.6)

    def act(self, obs):
        return {{k: [1.0, 0.0] for k in obs}}
"""

FAILS_IN_INIT = f"""import time
{BURN}

class Policy:
    def __init__(self):
        burn(0.8)
        raise RuntimeError("no model file")

    def act(self, obs):
        return {{}}
"""


@pytest.mark.parametrize("warm", [False, True], ids=["cold", "warm"])
def test_import_init_and_reset_are_charged_to_the_episode(
    warm: bool, kind, settings, labels, tmp
) -> None:
    submission = agent(tmp, settings, source=HEAVY_LOAD)
    with handle_of(submission, kind, settings, labels, warm) as handle:
        loaded = handle.episode_cpu_s
        handle.reset()
        reset = handle.episode_cpu_s
        handle.act(observation())
        acted = handle.episode_cpu_s
    # 0.6 s at import and 0.6 s in __init__ (1.2 s), then 0.6 s in reset: all the team's.
    assert loaded >= 1.1, loaded
    assert reset - loaded >= 0.55, (loaded, reset)
    assert acted >= reset


@pytest.mark.parametrize("warm", [False, True], ids=["cold", "warm"])
def test_loading_past_the_episode_budget_ends_the_episode(
    warm: bool, kind, settings, labels, tmp
) -> None:
    tight = with_fields(settings, sandbox={"episode_cpu_s": 1.0})
    submission = agent(tmp, tight, source=HEAVY_LOAD)
    with (
        pytest.raises(AgentFailed) as caught,
        handle_of(submission, kind, tight, labels, warm) as handle,
    ):
        handle.reset()
    assert caught.value.reason is DoneReason.episode_timeout
    assert caught.value.cpu_s > 1.0


def test_an_agent_failing_in_init_carries_the_cpu_it_used(kind, settings, labels, tmp) -> None:
    submission = agent(tmp, settings, source=FAILS_IN_INIT)
    with (
        pytest.raises(AgentFailed) as caught,
        handle_of(submission, kind, settings, labels, warm=False),
    ):
        pass
    assert caught.value.reason is DoneReason.agent_error
    assert caught.value.cpu_s >= 0.75, caught.value.cpu_s
