"""A Docker sandbox stopped from outside while its agent is healthy (``docker kill`` by an
operator, the daemon's restart) is ours, ``sandbox_error``, and its episode runs again; an agent
that ends itself, however it does it, stays the team's. Which one it was is read from the
daemon's events, which nothing inside a container can make: cold and warm (where the zygote's
container is the one stopped)."""

from __future__ import annotations

import threading
import time

import pytest

from arena.config import SandboxKind
from arena.errors import AgentFailed
from arena.outcome import DoneReason, Verdict, episode_verdict
from evaluator.sandbox.docker_backend import docker_client
from tests.evaluator.sandbox.agents import agent, handle_of, observation
from tests.evaluator.sandbox.conftest import usable
from tests.settings import with_fields

pytestmark = pytest.mark.docker

# An act long enough to be stopped in: waiting, so no CPU limit ends it first.
WAITS = "time.sleep(20)\nreturn {k: [1.0, 0.0] for k in obs}"
ROOMY = {"step_timeout_s": 60.0}


def stop_when_acting(labels: dict[str, str], stop) -> threading.Thread:
    """``stop(container)`` on the sandbox's container half a second from now, from outside."""
    selector = [f"{key}={value}" for key, value in labels.items()]

    def later() -> None:
        time.sleep(0.5)
        for container in docker_client().containers.list(filters={"label": selector}):
            stop(container)

    thread = threading.Thread(target=later)
    thread.start()
    return thread


@pytest.mark.parametrize("warm", [False, True], ids=["cold", "warm"])
@pytest.mark.parametrize(
    ("how", "stop", "signal"),
    [
        ("kill", lambda container: container.kill(), "SIGKILL"),
        ("stop", lambda container: container.stop(timeout=0), "SIGTERM"),
    ],
)
def test_a_sandbox_stopped_through_the_daemon_is_ours(
    how, stop, signal, warm, settings, labels, tmp
):
    usable(SandboxKind.docker, settings)
    roomy = with_fields(settings, sandbox=ROOMY)
    submission = agent(tmp, roomy, act=WAITS)
    with handle_of(submission, SandboxKind.docker, roomy, labels, warm) as handle:
        handle.reset()
        stopping = stop_when_acting(labels, stop)
        with pytest.raises(AgentFailed) as caught:
            handle.act(observation())
        stopping.join()
    assert caught.value.reason is DoneReason.sandbox_error, caught.value.detail
    assert f"stopped from outside by the Docker daemon ({signal})" in caught.value.detail
    assert episode_verdict([caught.value.reason]) is Verdict.ours


@pytest.mark.parametrize("warm", [False, True], ids=["cold", "warm"])
@pytest.mark.parametrize(
    "ends_itself", ["os._exit(3)", "os.kill(os.getpid(), 9)", "os.kill(os.getpid(), 15)"]
)
def test_an_agent_that_ends_itself_stays_the_teams(ends_itself, warm, settings, labels, tmp):
    usable(SandboxKind.docker, settings)
    submission = agent(tmp, settings, act=ends_itself)
    with handle_of(submission, SandboxKind.docker, settings, labels, warm) as handle:
        handle.reset()
        with pytest.raises(AgentFailed) as caught:
            handle.act(observation())
    assert caught.value.reason is DoneReason.agent_exited, caught.value.detail
    assert episode_verdict([caught.value.reason]) is Verdict.agent
