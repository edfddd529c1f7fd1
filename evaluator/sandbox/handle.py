"""The evaluator's handle on one running agent: the :class:`sim.agent.Agent` the simulator drives.

Every way an agent can fail is turned into one :class:`AgentFailed` with a named reason and the
tail of its stderr, after the sandbox has been killed: a failing agent never outlives its failure.

The episode's CPU is the team's from the moment its code is loaded: the runtime says hello before
it reads anything of the submission, and from then on every second the sandbox's meter reads
(importing ``policy.py``, ``Policy()``, ``reset``, every ``act``, ``close``, and whatever the
agent's threads do between them) is added to ``episode_cpu_s``, the episode's budget and the
evaluation's; a failure carries what was used up to it.

Each exchange with the team's code has its own limit of the same kind (a :class:`TimeLimit`): its
CPU time, read from the sandbox's meter, so that a busy worker charges the team nothing, and a
generous wall-clock backstop for an agent that waits or sleeps (where no meter reads CPU, the CPU
limit applies to the wall clock). Loading the policy (``ready``) and each ``reset`` have
``init_cpu_s`` and ``init_timeout_s`` (``init_timeout``), an act ``step_cpu_s`` and
``step_timeout_s`` (``step_timeout``). Before hello only our runtime runs: it has
``runtime_start_timeout_s`` of wall time, and missing it is ours (``sandbox_error``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NoReturn

from arena.config import SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.errors import AgentFailed
from arena.outcome import DoneReason
from evaluator.sandbox.array_frames import ArrayFrames
from evaluator.sandbox.backend import ExitStatus, Sandbox
from evaluator.sandbox.channel import Channel, ChannelClosed, ChannelTimeout, ChannelViolation
from evaluator.sandbox.cpu import CpuReader
from sim.agent import Observation
from sim.interface import AgentInterface, ObservationFormat

# How long a closing agent may take to say goodbye before it is killed [s].
CLOSE_GRACE_S = 1.0
# How long to wait for a dead agent's exit status after its stream closed [s].
EXIT_STATUS_WAIT_S = 2.0
# How often the CPU an unanswered act has used is read while waiting for its answer [s].
CPU_POLL_S = 0.25


@dataclass(frozen=True)
class TimeLimit:
    """What one exchange with the agent may take, charged ``reason`` when it takes more:
    ``cpu_s`` of the agent's CPU time (on the wall clock where no meter reads CPU) and ``wall_s``
    of wall time as the backstop. ``doing`` names the exchange in the failure's message."""

    reason: DoneReason
    doing: str
    cpu_s: float
    wall_s: float

    def deadline(self, cpu_from: float | None) -> float:
        """When to stop waiting: the backstop while the meter reads CPU (from ``cpu_from``),
        else the CPU limit itself."""
        return time.monotonic() + (self.wall_s if cpu_from is not None else self.cpu_s)


class AgentHandle:
    """A started agent. Made by :func:`evaluator.sandbox.start`, which has done hello/ready.
    ``interface``: the submission's ``agent.yaml``, whose observation format says how
    observations travel."""

    def __init__(
        self,
        sandbox: Sandbox,
        config: SandboxSettings,
        interface: AgentInterface | None = None,
        limits: CpuLimits | None = None,
    ) -> None:
        """``limits``: the run's CPU limits (a phase may override the settings')."""
        self._sandbox = sandbox
        self._arrays = (
            ArrayFrames(interface)
            if interface is not None and interface.observation_format is ObservationFormat.arrays
            else None
        )
        limits = limits or config.cpu_limits
        # run_episode then has the simulator write the arrays records in place, or pack the
        # waypoint paths of observation dicts for the runtime to unpack (sim.agent)
        self.takes_arrays = self._arrays is not None
        self.takes_packed_waypoints = self._arrays is None
        self.takes_agent_ids = True  # reset names the episode's agents (sim.agent)
        self._step = TimeLimit(
            DoneReason.step_timeout, "one act", limits.step_s, config.step_timeout_s
        )
        self._load = TimeLimit(
            DoneReason.init_timeout,
            "importing and building the policy",
            config.init_cpu_s,
            config.init_timeout_s,
        )
        self._reset = TimeLimit(
            DoneReason.init_timeout, "the policy's reset", config.init_cpu_s, config.init_timeout_s
        )
        self._episode_cpu_s = limits.episode_s
        # Our runtime's start, before hello: wall time, and ours.
        self._runtime_start_s = config.runtime_start_timeout_s
        self._meter: CpuReader | None = None
        self._cpu_mark: float | None = None  # the meter when last charged [s]
        self.episode_cpu_s = 0.0  # agent CPU time of this episode so far, from its loading [s]
        self._channel: Channel | None = None
        self._closed = False
        self.hello: dict[str, Any] = {}
        self.init_s: float | None = None
        # The libraries the agent imported, by module name, as the runtime in its sandbox
        # reported them at ready (the results manifest's agent_stack); bounded, strings only.
        self.stack: dict[str, str] = {}

    @classmethod
    def started(
        cls,
        sandbox: Sandbox,
        config: SandboxSettings,
        interface: AgentInterface | None = None,
        limits: CpuLimits | None = None,
    ) -> AgentHandle:
        """The handle of a launched ``sandbox`` once its agent said hello and ready; the sandbox
        is closed (killed) when the handshake fails, so a failed start leaves nothing running."""
        handle = cls(sandbox, config, interface, limits)
        try:
            handle.handshake()
        except BaseException:
            handle.close()
            raise
        return handle

    def handshake(self) -> None:
        deadline = time.monotonic() + self._runtime_start_s
        # Until hello the sandbox runs our runtime only (it says hello before it reads anything
        # of the submission): whatever ends it before then is ours (sandbox_error, not charged;
        # arena.outcome.verdict), after it the team's, under the loading's own limits.
        try:
            self._channel = self._sandbox.connect(deadline)
        except ChannelTimeout:
            self._fail(DoneReason.sandbox_error, "the sandbox did not start in time")
        except ChannelClosed:
            self._fail(DoneReason.sandbox_error, self._ended_detail("before the runner started"))
        meter = self._sandbox.cpu_meter()
        self._meter = meter.open() if meter is not None else None
        self.hello = self._expect("hello", deadline)
        # From here on the sandbox loads and runs the team's code: every CPU second is theirs.
        self._cpu_mark = started = self._cpu_now()
        deadline = self._load.deadline(started)
        ready = self._expect("ready", deadline, self._load, cpu_from=started)
        self._charge(self._load)
        init_s = ready.get("init_s")
        # The agent's own figure: kept only when it is a plain, sane number.
        self.init_s = (
            float(init_s) if isinstance(init_s, int | float) and 0 <= init_s < 1e9 else None
        )
        self.stack = reported_stack(ready.get("stack"))
        if self._arrays is not None:  # no answer: the runner keeps it for the act frames
            self._send("layout", self._arrays.layout.describe(), deadline, self._load.reason)

    def reset(self, agent_ids: Sequence[str] = ()) -> None:
        """A new episode of the agents ``agent_ids`` (all of them, those starting later too),
        within the start-up's CPU limit and wall-clock backstop, and the episode's CPU budget."""
        started = self._cpu_start()
        deadline = self._reset.deadline(started)
        self._send("reset", {"agents": list(agent_ids)}, deadline, self._reset.reason)
        self._expect("done", deadline, self._reset, cpu_from=started)
        self._charge(self._reset)

    def act(self, obs: dict[str, Observation]) -> dict[str, Any]:
        """The agent's actions for ``obs``, within the step's CPU limit (the wall clock where
        no meter reads CPU) and the wall-clock backstop, and the episode's CPU budget."""
        started = self._cpu_start()
        deadline = self._step.deadline(started)
        if self._arrays is None:
            self._send("act", obs, deadline, self._step.reason)
        else:
            self._send_frame(self._arrays.frame(obs), deadline)
        message = self._expect("actions", deadline, self._step, cpu_from=started)
        self._charge(self._step)
        actions = message.get("actions")
        if not isinstance(actions, dict):
            self._fail(DoneReason.agent_error, "protocol violation: actions are not a dict")
        return actions

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._channel is not None:
            deadline = time.monotonic() + CLOSE_GRACE_S
            try:
                self._channel.send("close", None, deadline)
                self._channel.receive(deadline)
            except (ChannelClosed, ChannelTimeout, ChannelViolation):
                pass
        self._account()  # what Policy.close() used, or the agent in the grace it had
        if self._meter is not None:
            self._meter.close()
        self._sandbox.kill()

    def logs(self) -> str:
        return self._sandbox.logs()

    def __enter__(self) -> AgentHandle:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _send(self, kind: str, body: Any, deadline: float, late: DoneReason) -> None:
        channel = self._open_channel()
        try:
            channel.send(kind, body, deadline)
        except ChannelTimeout:
            self._fail(late, f"the agent did not take its {kind} message in time")
        except ChannelClosed:
            self._died()

    def _send_frame(self, parts: list, deadline: float) -> None:
        channel = self._open_channel()
        try:
            channel.send_frame(parts, deadline)
        except ChannelTimeout:
            self._fail(DoneReason.step_timeout, "the agent did not take its act message in time")
        except ChannelClosed:
            self._died()

    def _open_channel(self) -> Channel:
        if self._closed or self._channel is None:
            raise AgentFailed(DoneReason.sandbox_error, "the agent was already closed")
        return self._channel

    def _cpu_now(self) -> float | None:
        return self._meter.seconds() if self._meter is not None else None

    def _cpu_start(self) -> float | None:
        """The meter's reading an exchange counts from: the last charge's (what the agent's
        threads used since is the exchange's too); None where no meter reads CPU."""
        if self._cpu_mark is None:
            self._cpu_mark = self._cpu_now()
        return self._cpu_mark

    def _account(self) -> float | None:
        """Add the CPU the sandbox used since the last mark to the episode's, and mark now;
        what was added [s] (None: nothing reads CPU, or nothing of the team's ran yet)."""
        if self._cpu_mark is None or self._meter is None:
            return None
        now = self._meter.seconds()
        if now is None:
            return None
        used = now - self._cpu_mark
        self._cpu_mark = now
        self.episode_cpu_s += used
        return used

    def _charge(self, limit: TimeLimit) -> None:
        """Charge an answered exchange: against its own CPU limit and the episode's budget."""
        used = self._account()
        if used is not None and used > limit.cpu_s:
            self._fail(
                limit.reason, f"{limit.doing} used {used:.2f} s of CPU (limit {limit.cpu_s:g} s)"
            )
        self._check_episode_budget()

    def _check_episode_budget(self) -> None:
        if self.episode_cpu_s > self._episode_cpu_s:
            self._fail(
                DoneReason.episode_timeout,
                f"the agent used {self.episode_cpu_s:.1f} s of CPU this episode "
                f"(limit {self._episode_cpu_s:g} s)",
            )

    def _receive(
        self, deadline: float, limit: TimeLimit | None, cpu_from: float | None
    ) -> dict[str, Any]:
        """The next message by ``deadline``; with ``cpu_from`` (a meter reading), also fail as
        soon as the agent has used more CPU than ``limit`` allows while we wait."""
        assert self._channel is not None
        if limit is None or cpu_from is None:
            return self._channel.receive(deadline)
        while True:
            try:
                return self._channel.receive(min(deadline, time.monotonic() + CPU_POLL_S))
            except ChannelTimeout:
                if time.monotonic() >= deadline:
                    raise
            now = self._cpu_now()
            if now is not None and now - cpu_from > limit.cpu_s:
                # Charged too (by _fail): the evaluation's budget counts what the exchange used.
                self._fail(
                    limit.reason,
                    f"{limit.doing} used more than {limit.cpu_s:g} s of CPU without answering",
                )

    def _expect(
        self,
        kind: str,
        deadline: float,
        limit: TimeLimit | None = None,
        *,
        cpu_from: float | None = None,
    ) -> dict[str, Any]:
        """The next message, of type ``kind``, within ``limit`` (None: our runtime's start,
        whose failures are ours) counted from the meter's ``cpu_from``."""
        assert self._channel is not None
        try:
            message = self._receive(deadline, limit, cpu_from)
        except ChannelTimeout:
            if limit is None:
                self._fail(DoneReason.sandbox_error, f"the runner did not say {kind} in time")
            if cpu_from is None:  # the CPU limit, on the wall clock
                self._fail(limit.reason, f"no {kind} within {limit.cpu_s:g} s")
            self._fail(limit.reason, f"no {kind} within {limit.wall_s:g} s of wall time")
        except ChannelClosed:
            if limit is None:
                self._fail(
                    DoneReason.sandbox_error, self._ended_detail("before the runner started")
                )
            self._died()
        except ChannelViolation as error:
            self._fail(DoneReason.agent_error, f"protocol violation: {error}")
        if message["type"] == "error":
            reason = (
                DoneReason.memory_limit
                if message.get("kind") == "memory"
                else DoneReason.agent_error
            )
            self._fail(reason, str(message.get("traceback") or message.get("message", "")))
        if message["type"] != kind:
            self._fail(
                DoneReason.agent_error, f"protocol violation: {message['type']!r} for {kind!r}"
            )
        return message

    def _died(self) -> NoReturn:
        status = self._sandbox.exit_status(EXIT_STATUS_WAIT_S)
        if status is not None and status.stopped_by:
            # Stopped from outside (an operator, the daemon's restart), not by anything the
            # agent did: ours, and the episode is run again (arena.outcome.episode_facts).
            self._fail(DoneReason.sandbox_error, "the agent's sandbox was " + status.describe())
        if status is not None and status.oom_killed:
            self._fail(DoneReason.memory_limit, "the agent was " + status.describe())
        self._fail(DoneReason.agent_exited, self._ended_detail("unexpectedly", status))

    def _ended_detail(self, when: str, status: ExitStatus | None = None) -> str:
        status = status or self._sandbox.exit_status(EXIT_STATUS_WAIT_S)
        how = status.describe() if status is not None else "stopped answering"
        return f"the agent {how} {when}"

    def _fail(self, reason: DoneReason, detail: str) -> NoReturn:
        self._closed = True
        self._account()  # read before the kill: a cgroup's counter goes with its sandbox
        self._sandbox.kill()
        tail = self._sandbox.logs()
        raise AgentFailed(reason, detail, tail, cpu_s=self.episode_cpu_s)


# What of a reported stack is kept: a report is the sandbox's word, so only a few short strings.
MAX_STACK_ENTRIES = 32
MAX_STACK_TEXT = 64


def reported_stack(reported: object) -> dict[str, str]:
    """The ``name -> version`` pairs of a ready message's ``stack`` that are short strings, at
    most :data:`MAX_STACK_ENTRIES` of them (nothing when it is not a dict)."""
    if not isinstance(reported, dict):
        return {}
    pairs = [
        (name, version)
        for name, version in reported.items()
        if isinstance(name, str)
        and isinstance(version, str)
        and len(name) <= MAX_STACK_TEXT
        and len(version) <= MAX_STACK_TEXT
    ]
    return dict(sorted(pairs)[:MAX_STACK_ENTRIES])
