"""A Docker sandbox stopped from outside while its agent is healthy (``docker kill`` by an
operator, the daemon's restart) is ours, ``sandbox_error``, and its episode runs again; an agent
that ends itself, however it does it, stays the team's. Which one it was is read from the
daemon's events, which nothing inside a container can make: cold and warm (where the zygote's
container is the one stopped), and for the batch sandboxes (training, checks, resolver)."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from arena.config import SandboxKind
from arena.errors import AgentFailed, SandboxUnavailable
from arena.outcome import DoneReason, Verdict, episode_verdict
from evaluator.sandbox import start_training
from evaluator.sandbox.backend import TRAIN_SCRIPT, Training
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


@pytest.mark.parametrize(
    ("train", "stopped"),
    [("import time; time.sleep(20)", True), ("raise SystemExit(3)", False)],
    ids=["stopped from outside", "exits itself"],
)
def test_a_batch_sandbox_stopped_from_outside_is_ours(train, stopped, settings, labels, tmp):
    """Training, an upload's checks and the resolver run as batches: one stopped from outside
    raises SandboxUnavailable (the job is retried, never charged); one that exits keeps its
    status for its caller to judge."""
    usable(SandboxKind.docker, settings)
    program, dataset, output = tmp / "program", tmp / "dataset", tmp / "output"
    for folder in (program, dataset, output):
        folder.mkdir()
        folder.chmod(0o777)
    (program / TRAIN_SCRIPT).write_text(train + "\n")
    box = start_training(
        SimpleNamespace(root=program, deps_dir=None),
        Training(dataset, output, timeout_s=60.0, output_bytes=1024**2),
        config=settings.sandbox,
        data_dir=settings.storage.resolved_data_dir,
        kind=SandboxKind.docker,
        labels=labels,
    )
    try:
        if stopped:
            stop_when_acting(labels, lambda container: container.kill()).join()
            with pytest.raises(SandboxUnavailable, match=r"stopped from outside by the Docker"):
                while box.exit_status(0.2) is None:
                    pass
        else:
            while (status := box.exit_status(0.2)) is None:
                pass
            assert (status.code, status.stopped_by) == (3, "")
    finally:
        box.kill()
