"""Hostile agents, in real sandboxes of every isolating backend.

Each case ends with its named reason (or, for actions the simulator judges, the action reaching
the caller unchanged), nothing of the agent is left running, and the next agent runs fine.
"""

from __future__ import annotations

import math
import shutil
import socket
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from arena.config import SandboxKind, Settings
from arena.errors import AgentFailed
from arena.outcome import DoneReason
from evaluator.sandbox import start
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.conftest import assert_clean_and_healthy
from tests.settings import sandbox_args, with_fields

REPO = Path(__file__).resolve().parents[3]
SCENARIO_SECRET = "/tmp/driving-arena-hidden-scenario/scenario.json"


@pytest.fixture(scope="module", autouse=True)
def hidden_scenario_on_the_host() -> Iterator[None]:
    """A scenario file on the host at a fixed path the hostile agents try to read."""
    secret = Path(SCENARIO_SECRET)
    secret.parent.mkdir(exist_ok=True)
    secret.write_text('{"hidden": true}')
    yield
    shutil.rmtree(secret.parent, ignore_errors=True)


@dataclass(frozen=True)
class Hostile:
    name: str
    act: str = "return {k: [1.0, 0.0] for k in obs}"
    init: str = "pass"
    # Failure expected when starting, when acting, or None: the agent keeps running.
    fails_at: str | None = "act"
    reason: DoneReason | None = DoneReason.agent_error
    # At least one of these appears in the failure detail.
    evidence: tuple[str, ...] = ()
    overrides: dict = field(default_factory=dict)


def framed(frame: str, then: str = "") -> str:
    """Agent code sending ``frame`` (a Python expression of bytes), length-prefixed as the
    protocol frames messages, down every descriptor the runtime may talk on; then ``then``."""
    return f"""
        frame = {frame}
        for fd in range(3, 16):
            try:
                os.write(fd, len(frame).to_bytes(4, 'big') + frame)
            except OSError:
                pass
        {then}
        """


CASES = [
    Hostile(
        "docker socket",
        act="socket.socket(socket.AF_UNIX).connect('/var/run/docker.sock')",
        evidence=("FileNotFoundError", "No such file"),
    ),
    Hostile(
        "reading the scenario folder",
        act=f"open({SCENARIO_SECRET!r}).read()",
        evidence=("FileNotFoundError",),
    ),
    Hostile(
        "reading the evaluator's code",
        act=f"open({str(REPO / 'arena' / 'config.py')!r}).read()",
        evidence=("FileNotFoundError",),
    ),
    Hostile(
        "writing outside /tmp",
        act="""
        open('/tmp/scratch', 'w').write('fine')
        open('model.bin', 'w').write('not fine')
        """,
        evidence=("Read-only file system", "Permission denied"),
    ),
    Hostile(
        "writing the root",
        act="open('/evil', 'w')",
        evidence=("Read-only file system", "Permission denied"),
    ),
    Hostile(
        "fork bomb",
        act="""
        for forked in range(500):
            try:
                pid = os.fork()
            except OSError as error:
                raise RuntimeError(f'fork refused after {forked} children') from error
            if pid == 0:
                time.sleep(120)
                os._exit(0)
        return {k: [1.0, 0.0] for k in obs}
        """,
        evidence=("fork refused",),
    ),
    Hostile(
        "allocating 8 GiB",
        init="self.ballast = np.ones(8 * 1024**3, dtype=np.uint8)",
        fails_at="start",
        reason=DoneReason.memory_limit,
        # Filling the memory limit takes seconds on a loaded machine: it must fail by the limit,
        # never by the start-up deadline.
        overrides={"sandbox": {"init_timeout_s": 120.0}},
    ),
    Hostile("spinning the CPU in act", act="while True: pass", reason=DoneReason.step_timeout),
    Hostile("sleeping past the deadline", act="time.sleep(30)", reason=DoneReason.step_timeout),
    Hostile(
        "sleeping past the init deadline",
        init="time.sleep(60)",
        fails_at="start",
        reason=DoneReason.init_timeout,
        overrides={"sandbox": {"init_timeout_s": 3.0}},
    ),
    Hostile("exiting in act", act="os._exit(3)", reason=DoneReason.agent_exited),
    Hostile(
        "raising in __init__",
        init="raise ValueError('broken on purpose')",
        fails_at="start",
        evidence=("ValueError: broken on purpose",),
    ),
    Hostile(
        "importing a missing module",
        init="import not_a_module_anyone_has",
        fails_at="start",
        evidence=("ModuleNotFoundError",),
    ),
    Hostile(
        "writing garbage into the protocol",
        act="""
        for fd in range(3, 16):
            try:
                os.write(fd, b'\\x00\\x00\\x00\\x05hello')
            except OSError:
                pass
        return {k: [1.0, 0.0] for k in obs}
        """,
        evidence=("protocol violation",),
    ),
    Hostile(
        # json's recursive decoder raised an uncaught RecursionError: an uncharged error of ours.
        "a deeply nested frame before ready",
        init=framed("b'[' * 200_000"),
        fails_at="start",
        evidence=("nested more than",),
    ),
    Hostile(
        # An integer of more than 4300 digits: json raised an uncaught ValueError.
        "a 5000-digit integer in a frame",
        act=framed(
            """b'{"type": "actions", "actions": {"Agent_0": [' + b'9' * 5000 + b', 0]}}'""",
            then="time.sleep(5)",
        ),
        evidence=("protocol violation", "not JSON"),
    ),
    Hostile(
        # Replies are UTF-8 JSON: json.loads would have taken this one, sniffing UTF-16 bytes.
        "a frame of UTF-16 JSON",
        act=framed(
            """'{"type": "actions", "actions": {}}'.encode('utf-16')""", then="time.sleep(5)"
        ),
        evidence=("protocol violation", "not JSON"),
    ),
    Hostile("raising in act", act="raise KeyError('lost')", evidence=("KeyError: 'lost'",)),
    Hostile(
        "returning a list, not a dict",
        act="return [1.0, 0.0]",
        evidence=("must return a dict",),
    ),
    Hostile(
        "returning something not JSON",
        act="return {k: object() for k in obs}",
        evidence=("not a number",),
    ),
]


# Both ways observations travel: pickled dicts, or binary frames of arrays.
FORMATS = ["native", "arrays"]


@pytest.mark.parametrize("observation_format", FORMATS)
@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_hostile_agent_fails_with_its_reason(
    case: Hostile,
    observation_format: str,
    kind: SandboxKind,
    settings: Settings,
    labels,
    good_agent,
    tmp: Path,
) -> None:
    run_settings = with_fields(settings, **case.overrides)
    submission = agent(
        tmp,
        run_settings,
        act=case.act,
        init=case.init,
        agent_yaml=f"observation_format: {observation_format}\n",
    )
    with pytest.raises(AgentFailed) as caught:
        handle = start(
            submission,
            kind=kind,
            labels=labels,
            **sandbox_args(run_settings),
        )
        assert case.fails_at == "act", "the agent should not have started"
        with handle:
            handle.reset()
            handle.act(observation())
    failure = caught.value
    assert failure.reason is case.reason, failure
    if case.evidence:
        assert any(text in failure.detail for text in case.evidence), failure.detail
    assert_clean_and_healthy(kind, labels, settings, good_agent)


def test_printing_100_mb_keeps_the_last_64_kib(kind, settings, labels, good_agent, tmp) -> None:
    init = """
    chunk = 'x' * 999_999 + '\\n'
    for _ in range(100):
        sys.stderr.write(chunk)
    print('stdout is the log too')
    sys.stderr.write('THE END\\n')
    sys.stderr.flush()
    """
    submission = agent(tmp, settings, init=init)
    with start(
        submission,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        assert handle.act(observation()) == {"Agent_0": [1.0, 0.0]}
        handle.close()
        logs = handle.logs()
    assert len(logs.encode()) <= settings.sandbox.agent_log_tail_bytes
    assert logs.endswith("stdout is the log too\nTHE END\n")
    assert_clean_and_healthy(kind, labels, settings, good_agent)


def test_killing_its_parent_changes_nothing(kind, settings, labels, good_agent, tmp) -> None:
    """The agent's parent is the sandbox's init, which ignores signals from inside; ``kill(-1)``
    reaches only the sandbox's own processes."""
    act = """
    os.kill(os.getppid(), 9)
    try:
        os.kill(-1, 9)  # every process it may signal, but there is none but itself
    except ProcessLookupError:
        pass
    return {k: [float(os.getppid()), 0.0] for k in obs}
    """
    submission = agent(tmp, settings, act=act)
    with start(
        submission,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        first = handle.act(observation())
        assert handle.act(observation()) == first
    assert_clean_and_healthy(kind, labels, settings, good_agent)


@pytest.mark.parametrize(
    ("name", "act", "check"),
    [
        ("NaN action", "return {k: [float('nan'), 0.0, 0.0, 0.1] for k in obs}", "nan"),
        ("wrong-length action", "return {k: [1.0] for k in obs}", {"Agent_0": [1.0]}),
        ("missing agent id", "return {}", {}),
        ("unknown agent id", "return {'Agent_9': [1.0, 0.0]}", {"Agent_9": [1.0, 0.0]}),
        ("huge integer", "return {k: [10**400, 0.0] for k in obs}", {"Agent_0": [10**400, 0]}),
        ("numpy action", "return {k: np.array([2.0, 1.0], dtype=np.float32) for k in obs}",
         {"Agent_0": [2.0, 1.0]}),
    ],
)  # fmt: skip
def test_actions_the_simulator_judges_arrive_unchanged(
    name: str, act: str, check, kind, settings, labels, good_agent, tmp
) -> None:
    """invalid_action is the simulator's call: the sandbox delivers the action as sent."""
    submission = agent(tmp, settings, act=act)
    with start(
        submission,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        actions = handle.act(observation())
        if check == "nan":
            assert math.isnan(actions["Agent_0"][0]) and actions["Agent_0"][1:] == [0.0, 0.0, 0.1]
        else:
            assert actions == check
        # The agent is still fine after an action the simulator will refuse.
        assert handle.act(observation()) == actions or check == "nan"
    assert_clean_and_healthy(kind, labels, settings, good_agent)


@pytest.fixture
def host_listener() -> Iterator[socket.socket]:
    """A TCP listener on the host's loopback: a sandbox with any network would reach it."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(8)
        listener.setblocking(False)
        yield listener


def test_no_network_inside_the_sandbox(
    host_listener, kind, settings, labels, good_agent, tmp
) -> None:
    """Proved by what the agent sees, without sending a packet off the machine: no interface but
    ``lo``, and a listener on the host's 127.0.0.1 is not reachable from inside."""
    port = host_listener.getsockname()[1]
    act = f"""
    names = sorted(name for _, name in socket.if_nameindex())
    try:
        socket.create_connection(('127.0.0.1', {port}), timeout=3).close()
        reached = 'reached the host'
    except OSError as error:
        reached = f'unreachable ({{error.errno}})'
    raise RuntimeError(f'interfaces={{names}} host-listener={{reached}}')
    """
    submission = agent(tmp, settings, act=act)
    with (
        pytest.raises(AgentFailed) as caught,
        start(
            submission,
            kind=kind,
            labels=labels,
            **sandbox_args(settings),
        ) as handle,
    ):
        handle.reset()
        handle.act(observation())
    assert "interfaces=['lo'] host-listener=unreachable" in caught.value.detail
    with pytest.raises(BlockingIOError):
        host_listener.accept()  # nothing ever connected
    assert_clean_and_healthy(kind, labels, settings, good_agent)
