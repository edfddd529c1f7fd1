"""Warm agents: one sandbox per submission that forks a fresh agent for every episode.

Starting a sandbox costs far more than an episode's first step (a Docker container about 0.35 s,
then the interpreter and numpy), so :class:`WarmAgent` starts one with the runner in its zygote
mode (``agent_runtime/zygote.py``) and keeps it. For each episode, :meth:`WarmAgent.fork` makes
three socket pairs and passes one end of each to the zygote, which forks the episode's agent:

- the **protocol** socket, on which the agent says hello and ready and answers as always;
- the **lifeline**: any byte on it (or its closing) kills the agent, and the zygote answers on it
  with the agent's exit status once the sandbox is clean again;
- the **log**: the agent's stdout and stderr.

The other ends travel in a :class:`ForkedAgent` to the simulator's episode process, where
:class:`ForkedSandbox` plays the part of a started sandbox for :class:`AgentHandle`, so the agent
fails, times out and is killed exactly as a cold one. The evaluating process keeps its own copy
of the lifeline: ``evaluator.sandbox.cleanup(config, labels)`` pulls it to kill a leased agent.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import pickle
import select
import socket
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from arena.config import SandboxKind, SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.errors import SandboxUnavailable
from evaluator.sandbox.backend import SANDBOX_LABEL, ExitStatus, LaunchSpec, Sandbox
from evaluator.sandbox.backend_registry import backend_for
from evaluator.sandbox.channel import (
    HEADER,
    Channel,
    ChannelClosed,
    ChannelTimeout,
    ChannelViolation,
)
from evaluator.sandbox.cpu import CpuMeter
from evaluator.sandbox.docker_backend import DockerSandbox, daemon_stop
from evaluator.sandbox.handle import AgentHandle
from evaluator.sandbox.subprocess_sandbox import LogTail
from sim.interface import AgentInterface

log = logging.getLogger(__name__)

# Every zygote's sandbox carries this label besides the usual ones.
WARM_LABEL = "driving-arena.warm"
# How long a killed agent's zygote may take to report it dead and the sandbox clean [s].
KILL_WAIT_S = 5.0
STATUS_MAX_BYTES = 4096


@dataclass
class ForkedAgent:
    """The evaluator's ends of one forked agent's channels. Picklable into the episode process
    (multiprocessing passes the sockets' descriptors along)."""

    protocol: socket.socket
    lifeline: socket.socket
    log: socket.socket
    config: SandboxSettings
    labels: dict[str, str] = field(default_factory=dict)
    interface: AgentInterface | None = None  # the submission's agent.yaml
    meter: CpuMeter | None = None  # the zygote's sandbox: its idle parent uses no CPU
    # The zygote's container and when it was launched, under Docker: whether the daemon stopped
    # it is asked when the zygote ends without saying how this agent did.
    zygote_container: tuple[str, float] | None = None

    def kill(self) -> None:
        """Ask the zygote to kill this agent (it may be gone already)."""
        with contextlib.suppress(OSError):
            self.lifeline.send(b"k", socket.MSG_NOSIGNAL)

    def close(self) -> None:
        for end in (self.protocol, self.lifeline, self.log):
            end.close()

    def start(self, limits: CpuLimits | None = None) -> AgentHandle:
        """The agent's handle, after its hello and ready (in the episode process); its acts
        run under ``limits`` (default: the sandbox settings')."""
        return AgentHandle.started(ForkedSandbox(self), self.config, self.interface, limits)


class ForkedSandbox:
    """:class:`~evaluator.sandbox.backend.Sandbox` of one forked agent."""

    def __init__(self, agent: ForkedAgent) -> None:
        self._agent = agent
        self._stderr = LogTail(agent.log, agent.config.agent_log_tail_bytes)
        self._status: ExitStatus | None = None
        self._status_read = False

    def connect(self, deadline: float) -> Channel:
        fd = self._agent.protocol.fileno()
        return Channel(fd, fd)

    def exit_status(self, timeout: float) -> ExitStatus | None:
        if not self._status_read:
            lifeline = self._agent.lifeline
            ready, _, _ = select.select([lifeline], [], [], max(timeout, 0))
            if not ready:
                return None
            self._status_read = True
            self._status = read_exit_status(lifeline)
            if self._status.code is None and self._agent.zygote_container is not None:
                stopped = daemon_stop(*self._agent.zygote_container, time.time())
                self._status = replace(self._status, stopped_by=stopped)
        return self._status

    def kill(self) -> None:
        if not self._status_read:
            self._agent.kill()
            self.exit_status(KILL_WAIT_S)
        self._agent.protocol.close()
        self._agent.lifeline.close()
        self._stderr.text(wait=1.0)
        self._agent.log.close()

    def logs(self) -> str:
        return self._stderr.text(wait=0.5 if self._status_read else 0.0)

    def cpu_meter(self) -> CpuMeter | None:
        return self._agent.meter


def read_exit_status(lifeline: socket.socket) -> ExitStatus:
    """The zygote's ``exited`` frame; an unknown end when it died first."""
    data = bytearray()
    lifeline.settimeout(KILL_WAIT_S)
    with contextlib.suppress(OSError):
        while len(data) < STATUS_MAX_BYTES and (chunk := lifeline.recv(STATUS_MAX_BYTES)):
            data += chunk
    try:
        status = json.loads(data[HEADER.size :])
        return ExitStatus(int(status["code"]), oom_killed=bool(status["oom"]))
    except (ValueError, KeyError, TypeError):
        return ExitStatus(None)


class WarmAgent:
    """A started zygote in its sandbox, forking agents one episode at a time."""

    def __init__(
        self, sandbox: Sandbox, channel: Channel, kind: SandboxKind, interface: AgentInterface
    ) -> None:
        self._sandbox = sandbox
        self._channel = channel
        self.kind = kind
        self.interface = interface  # the submission's agent.yaml, for its forked agents
        self.last_used = time.monotonic()
        self._closed = False
        self.meter = sandbox.cpu_meter()
        self.settling = False  # its last episode ended; its "ready" not read yet

    @classmethod
    def start(
        cls,
        submission,
        kind: SandboxKind,
        config: SandboxSettings,
        data_dir: Path,
        labels: dict[str, str] | None = None,
        cpus: tuple[int, ...] | None = None,
    ) -> WarmAgent:
        """Start ``submission``'s zygote, on ``cpus`` (those of the job it serves; its agents
        inherit them). Raises :class:`SandboxUnavailable` when it does not say hello and ready
        in ``runtime_start_timeout_s`` of wall time: it runs none of the participant's code, so
        that is ours (the caller then starts each agent cold, which reports the agent's own
        errors).
        Each forked agent then loads the policy under the start-up's CPU limit
        (:class:`AgentHandle`), as a cold one does."""
        spec = LaunchSpec.of_agent(
            submission,
            config,
            data_dir,
            {**(labels or {}), WARM_LABEL: "1"},
            zygote=True,
            cpus=cpus,
        )
        sandbox = backend_for(kind).launch(spec)
        deadline = time.monotonic() + config.runtime_start_timeout_s
        try:
            channel = sandbox.connect(deadline)
            hello = channel.receive(deadline)
            ready = channel.receive(deadline)
            if hello.get("zygote") is not True or ready.get("type") != "ready":
                raise SandboxUnavailable(f"the agent zygote did not start: {hello} {ready}")
        except (ChannelClosed, ChannelTimeout, SandboxUnavailable) as error:
            logs = sandbox.logs()
            sandbox.kill()
            detail = f"the agent zygote did not start ({error!r}): {logs}"
            raise SandboxUnavailable(detail) from error
        except BaseException:
            sandbox.kill()
            raise
        return cls(sandbox, channel, kind, submission.interface)

    def fork(self, config: SandboxSettings, labels: dict[str, str]) -> ForkedAgent:
        """A new agent for one episode. Raises :class:`SandboxUnavailable` when the zygote is
        gone."""
        ours, theirs = zip(*(socket.socketpair() for _ in range(3)), strict=True)
        try:
            buffer = io.BytesIO()
            pickle.dump(("fork", None), buffer, protocol=5)
            frame = HEADER.pack(buffer.getbuffer().nbytes) + buffer.getvalue()
            # A few bytes into an idle socket: the non-blocking send does not fall short.
            control = socket.socket(fileno=os.dup(self._channel.write_fd))
            try:
                socket.send_fds(control, [frame], [end.fileno() for end in theirs])
            finally:
                control.close()
        except OSError as error:
            for end in ours:
                end.close()
            raise SandboxUnavailable(f"the agent zygote is gone: {error}") from error
        finally:
            for end in theirs:
                end.close()
        self.last_used = time.monotonic()
        return ForkedAgent(
            *ours,
            config=config,
            labels={SANDBOX_LABEL: "1", **labels},
            interface=self.interface,
            meter=self.meter,
            zygote_container=(
                (self._sandbox.container.id, self._sandbox.launched)
                if isinstance(self._sandbox, DockerSandbox)
                else None
            ),
        )

    def wait_ready(self, timeout: float) -> bool:
        """Whether the zygote, after its last agent, says the sandbox is clean and it is ready
        for the next fork within ``timeout`` seconds (it says nothing and exits when not)."""
        try:
            message = self._channel.receive(time.monotonic() + timeout)
        except (ChannelClosed, ChannelTimeout, ChannelViolation):
            return False
        return message.get("type") == "ready"

    def settled(self, timeout: float) -> bool:
        """Whether it can fork now: its last episode's ``ready`` came (within ``timeout``
        seconds) and it still waits for requests."""
        if self.settling:
            if not self.wait_ready(timeout):
                return False
            self.settling = False
        return self.alive()

    def alive(self) -> bool:
        """Whether the zygote still waits for requests (it never writes on its own: anything
        readable is its end of the stream)."""
        if self._closed:
            return False
        poller = select.poll()
        poller.register(self._channel.read_fd, select.POLLIN)
        return not poller.poll(0)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(ChannelClosed, ChannelTimeout, OSError):
            self._channel.send("close", None, time.monotonic() + 1.0)
        try:
            self._sandbox.kill()
        except SandboxUnavailable as error:
            # The episodes it served are over and kept; a sandbox the daemon already removed
            # (``arena sandbox cleanup``) must not turn them into errors.
            log.warning("closing a warm agent: %s", error)
