"""Episode processes that run one episode after another, so that an episode does not pay for a
process of its own.

:func:`sim.isolation.run_episode_isolated` forks a process for every episode from the
simulator's fork server. Measured over the hidden suite's later episodes (docs/performance.md
"Per-episode start"), that costs each one: starting the process through the fork server, the
scenario's inputs unpickled again, and every page the episode writes copied or faulted in anew
(``libsumo.start`` alone takes 8 ms of CPU in a fresh fork against 4.7 ms in a process that has
run one before). An :class:`EpisodeWorker` is one such process that stays: it runs the episodes
it is sent one at a time, and keeps what a scenario's later episodes would load again, the parsed
inputs by content (:class:`InputsKept`). What stays as before:

- the evaluating process never imports libsumo, and an episode's crash, hang or SUMO failure is
  a ``simulator_error`` that never raises here (the worker is then killed and replaced);
- every episode starts its own SUMO (``libsumo.start`` with its seed; libsumo holds one
  simulation per process) and gets its agent from its factory, as in its own process;
- nothing of an episode reaches the next but the inputs, which no episode writes (a replay's
  table is copied per episode, :meth:`sim.playback.ReplayTable.fresh`): the records of an
  episode are the same bytes whichever episodes the worker ran before
  (``tests/sim/test_episode_workers.py``).

A worker retires after :data:`EPISODES_PER_WORKER` episodes and when idle for
:data:`IDLE_S`, which bounds what a long-lived process could accumulate (SUMO's own
allocations). :class:`EpisodeWorkers` keeps the idle ones of an evaluating process; each
caller (an evaluation's job) takes one for an episode and gives it back. They close at exit,
and when the evaluations of their process end, which may go on (a script, a notebook):
``evaluator.runner.evaluate`` runs its episodes in :meth:`EpisodeWorkers.serving`, and a
service worker, whose episodes are tasks of their own, closes them when none of its submissions
is in work any more (``server/worker/local.py``, at its reaper's next round). No simulator
process waits out the idle time after the work that needed it.

The request travels as a pickle over a socket pair, the descriptors it holds (an agent's
sockets, the inputs' memory file) beside it as ancillary data: unlike the fork server, a running
process can only be handed descriptors that way.
"""

from __future__ import annotations

import atexit
import io
import multiprocessing as mp
import os
import pickle
import select
import socket
import struct
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from sim.agent import Agent
from sim.interface import AgentInterface
from sim.isolation import (
    episode_in_this_process,
    failed_result,
    preload_modules,
    run_episode_isolated,
    start_without_main,
    wall_timeout,
)
from sim.result import EpisodeResult

# Episodes one worker runs before it is replaced: bounds what SUMO's allocations could leave.
EPISODES_PER_WORKER = 200
# An idle worker is closed after this long [s]: it holds a simulator's memory.
IDLE_S = 120.0
# Parsed inputs a worker keeps, by the bytes of their pickles (a scenario's episodes run
# together, so a few scenarios suffice; a whole hidden suite's pickles are about 70 MB).
KEPT_INPUTS_BYTES = 64 * 2**20
HEADER = struct.Struct(">Q")
MAX_DESCRIPTORS = 16


@dataclass(frozen=True)
class _Request:
    scenario_dir: Path
    agent_factory: Callable[[], Agent]
    interface: AgentInterface
    record_path: Path
    seed: int | None
    wall_timeout_s: float
    inputs_key: str | None  # the content key of the inputs (sim.inputs), None: not parsed
    cwd: str  # the caller's: relative paths mean what they mean there, as in a spawned process


class InputsKept:
    """A worker's parsed inputs by content key, least recently used dropped past ``limit``
    bytes of their pickles (the newest is always kept)."""

    def __init__(self, limit: int = KEPT_INPUTS_BYTES) -> None:
        self.limit = limit
        self._kept: OrderedDict[str, tuple[object, int]] = OrderedDict()

    def take(self, key: str | None, fd: int | None):
        """The inputs of ``key``: kept ones, or read from memory file ``fd`` (closed either
        way) and kept; None when there are none."""
        # deferred: the inputs module is the episode processes'
        from sim.inputs import read_inputs

        if fd is None or key is None:
            if fd is not None:
                os.close(fd)
            return None
        if key in self._kept:
            os.close(fd)
            self._kept.move_to_end(key)
            return self._kept[key][0]
        size = os.fstat(fd).st_size
        inputs = read_inputs(fd)
        if inputs.replay is not None:
            # The recording's rows by step and their nearest lanes, worked out at a replay's
            # first step, once here: each episode's copy (ReplayTable.fresh) shares them.
            inputs.replay.states(0)
        self._kept[key] = (inputs, size)
        while sum(s for _, s in self._kept.values()) > self.limit and len(self._kept) > 1:
            self._kept.popitem(last=False)
        return inputs

    def __contains__(self, key: str) -> bool:
        return key in self._kept


class _Descriptors(pickle.Pickler):
    """Pickles sockets as their place in the list of descriptors sent beside the pickle."""

    def __init__(self, file) -> None:
        super().__init__(file, protocol=5)
        self.fds: list[int] = []

    def persistent_id(self, obj):
        if isinstance(obj, socket.socket):
            self.fds.append(obj.fileno())
            return ("socket", len(self.fds) - 1, obj.family, obj.type)
        return None


class _Sockets(pickle.Unpickler):
    """Unpickles what :class:`_Descriptors` pickled: a socket of each descriptor received."""

    def __init__(self, file, fds: list[int]) -> None:
        super().__init__(file)
        self.fds = fds
        self.sockets: list[socket.socket] = []

    def persistent_load(self, pid):
        _, index, family, kind = pid
        made = socket.socket(family, kind, fileno=self.fds[index])
        self.sockets.append(made)
        return made


def _send(sock: socket.socket, payload: bytes, fds: list[int]) -> None:
    data = HEADER.pack(len(payload)) + payload
    sent = socket.send_fds(sock, [data], fds) if fds else sock.send(data)
    sock.sendall(memoryview(data)[sent:])


def _receive(sock: socket.socket) -> tuple[bytes, list[int]] | None:
    """A message and the descriptors that came with it; None when the other end closed."""
    data, fds, _, _ = socket.recv_fds(sock, 1 << 16, MAX_DESCRIPTORS)
    if not data:
        for fd in fds:
            os.close(fd)
        return None
    buffer = bytearray(data)
    while len(buffer) < HEADER.size:
        more = sock.recv(1 << 16)
        if not more:
            return None
        buffer += more
    (size,) = HEADER.unpack_from(buffer)
    end = HEADER.size + size
    while len(buffer) < end:
        more = sock.recv(max(end - len(buffer), 1 << 16))
        if not more:
            return None
        buffer += more
    return bytes(buffer[HEADER.size : end]), fds


def _serve(sock: socket.socket) -> None:
    """A worker's life: episodes until the evaluating process closes the socket."""
    # deferred: only the episode processes simulate
    from sim.episode import describe_exception

    kept = InputsKept()
    while True:
        received = _receive(sock)
        if received is None:
            return
        payload, fds = received
        unpickler = _Sockets(io.BytesIO(payload), fds)
        request, with_inputs = unpickler.load()
        try:
            os.chdir(request.cwd)
            parsed = kept.take(request.inputs_key, fds[-1] if with_inputs else None)
        except Exception as exc:  # as an episode process's unreadable inputs: SUMO's side
            reply = (f"{type(exc).__name__}: {exc}", describe_exception(exc))
        else:
            reply = episode_in_this_process(
                request.scenario_dir,
                request.agent_factory,
                request.interface,
                request.record_path,
                request.seed,
                wall_timeout_s=request.wall_timeout_s,
                parsed=parsed,
            )
        finally:
            # The agent's descriptors end with its episode (a closed socket closes no more).
            for made in unpickler.sockets:
                made.close()
        try:
            _send(sock, pickle.dumps(reply, protocol=5), [])
        except OSError:  # the evaluating process gave up on this episode (its hard limit)
            return


class EpisodeWorker:
    """One long-lived episode process, forked from the simulator's fork server."""

    def __init__(self, agent_factory: Callable[[], Agent]) -> None:
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(preload_modules(agent_factory))
        self.sock, theirs = socket.socketpair()
        # Daemonic: multiprocessing's exit handler, which may run before ours, ends it instead
        # of waiting for it (it would wait for its next episode forever).
        self.process = ctx.Process(
            target=_serve, args=(theirs,), name="episode-worker", daemon=True
        )
        try:
            start_without_main(self.process, agent_factory)
        finally:
            theirs.close()
        self.episodes = 0
        self.last_used = time.monotonic()
        self.last_inputs: str | None = None  # the content key of its last episode's inputs

    def run(
        self,
        scenario_dir: Path,
        agent_factory: Callable[[], Agent],
        interface: AgentInterface,
        *,
        record_path: Path,
        seed: int | None,
        timeout_s: float,
        episode_timeout_s: float | None,
        inputs: tuple[str, int] | None,
    ) -> EpisodeResult:
        """The episode's result; a failure of the process is a ``simulator_error`` result, after
        which this worker is closed. ``inputs``: the content key and a memory file of the
        scenario's parsed inputs (:mod:`sim.inputs`), closed here."""
        started = time.monotonic()
        self.episodes += 1
        key, fd = inputs if inputs is not None else (None, None)
        request = _Request(
            Path(scenario_dir),
            agent_factory,
            interface,
            Path(record_path),
            seed,
            wall_timeout(timeout_s, episode_timeout_s),
            key,
            os.getcwd(),
        )
        buffer = io.BytesIO()
        pickler = _Descriptors(buffer)
        try:
            pickler.dump((request, fd is not None))
            # The inputs' memory file goes last (after the agent's sockets the pickle names).
            _send(self.sock, buffer.getvalue(), pickler.fds + ([fd] if fd is not None else []))
            reply = self._reply(timeout_s)
        except OSError:
            reply = None
        finally:
            if fd is not None:
                os.close(fd)  # the worker has its own now
        self.last_used = time.monotonic()
        self.last_inputs = key
        if isinstance(reply, EpisodeResult):
            return reply
        elapsed = time.monotonic() - started
        if reply is None:
            self.kill()
            if elapsed >= timeout_s:
                error = f"episode process exceeded {timeout_s:.0f} s and was killed"
            else:
                error = f"episode process died (exit code {self.process.exitcode})"
            return failed_result(scenario_dir, error, "", elapsed)
        error, detail = reply
        return failed_result(scenario_dir, error, detail, elapsed)

    def _reply(self, timeout_s: float):
        """The worker's answer, or None when it died or did not answer in time."""
        ready, _, _ = select.select([self.sock], [], [], timeout_s)
        if not ready:
            return None
        received = _receive(self.sock)
        if received is None:
            return None
        payload, _ = received
        return pickle.loads(payload)

    def alive(self) -> bool:
        return self.sock.fileno() >= 0 and self.process.is_alive()

    def close(self) -> None:
        """End the worker between episodes: it leaves when its socket closes (killed when it
        does not within a few seconds)."""
        self.sock.close()
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.kill()

    def kill(self) -> None:
        self.sock.close()
        if self.process.is_alive():
            self.process.kill()
        self.process.join()


class EpisodeWorkers:
    """The episode workers of one evaluating process: a caller takes an idle one (one that ran
    the same scenario last when there is one: it kept its inputs) or a new one, runs an
    episode and gives it back. Thread-safe: an evaluation's jobs share it."""

    def __init__(
        self, episodes_per_worker: int = EPISODES_PER_WORKER, idle_s: float = IDLE_S
    ) -> None:
        self.episodes_per_worker = episodes_per_worker
        self.idle_s = idle_s
        self._idle: list[EpisodeWorker] = []
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self._evaluations = 0  # under way in :meth:`serving`

    def run_episode(
        self,
        scenario_dir: Path,
        agent_factory: Callable[[], Agent],
        interface: AgentInterface,
        *,
        record_path: Path,
        seed: int | None = None,
        timeout_s: float = 900,
        episode_timeout_s: float | None = None,
    ) -> EpisodeResult:
        """:func:`sim.isolation.run_episode_isolated`'s contract, in an episode worker. A
        factory defined in the main script (which a worker does not run) gets a process of its
        own as there."""
        # deferred: only the episode processes simulate
        from sim.inputs import packed_inputs

        if _defined_in_main(agent_factory):
            return run_episode_isolated(
                scenario_dir,
                agent_factory,
                interface,
                record_path=record_path,
                seed=seed,
                timeout_s=timeout_s,
                episode_timeout_s=episode_timeout_s,
            )
        inputs = packed_inputs.open_keyed(Path(scenario_dir))
        worker = self._take(inputs[0] if inputs else None, agent_factory)
        result = worker.run(
            scenario_dir,
            agent_factory,
            interface,
            record_path=record_path,
            seed=seed,
            timeout_s=timeout_s,
            episode_timeout_s=episode_timeout_s,
            inputs=inputs,
        )
        self._give_back(worker)
        return result

    @contextmanager
    def serving(self) -> Iterator[None]:
        """Around an evaluation: its episodes share the workers (as do those of evaluations
        running beside it), and when the last evaluation under way ends, the idle workers
        close."""
        with self._lock:
            self._evaluations += 1
        try:
            yield
        finally:
            with self._lock:
                self._evaluations -= 1
                last = self._evaluations == 0
            if last:
                self.close()

    def close(self) -> None:
        """End the idle workers (one running an episode is not idle: it is given back after
        it, and the idle timer ends it if nothing takes it again)."""
        with self._lock:
            closing, self._idle = self._idle, []
        for worker in closing:
            worker.close()

    def close_idle(self) -> None:
        cutoff = time.monotonic() - self.idle_s
        with self._lock:
            closing = [w for w in self._idle if w.last_used <= cutoff]
            self._idle = [w for w in self._idle if w.last_used > cutoff]
        for worker in closing:
            worker.close()

    def _take(self, key: str | None, agent_factory) -> EpisodeWorker:
        with self._lock:
            alive = [w for w in self._idle if w.alive()]
            dead = [w for w in self._idle if not w.alive()]
            same = [w for w in alive if key is not None and w.last_inputs == key]
            worker = (same or alive or [None])[-1]
            self._idle = [w for w in alive if w is not worker]
        for gone in dead:
            gone.kill()
        return worker or EpisodeWorker(agent_factory)

    def _give_back(self, worker: EpisodeWorker) -> None:
        if not worker.alive() or worker.episodes >= self.episodes_per_worker:
            worker.close()
            return
        with self._lock:
            self._idle.append(worker)
            if self._timer is None:
                self._timer = threading.Timer(self.idle_s, self._on_timer)
                self._timer.daemon = True
                self._timer.start()

    def _on_timer(self) -> None:
        with self._lock:
            self._timer = None
        self.close_idle()
        with self._lock:
            if self._idle and self._timer is None:
                self._timer = threading.Timer(self.idle_s, self._on_timer)
                self._timer.daemon = True
                self._timer.start()


def _defined_in_main(agent_factory) -> bool:
    factory = getattr(agent_factory, "func", agent_factory)  # a functools.partial's function
    return getattr(factory, "__module__", None) == "__main__"


@lru_cache(maxsize=1)
def episode_workers() -> EpisodeWorkers:
    """This process's episode workers, closed at exit."""
    workers = EpisodeWorkers()
    atexit.register(workers.close)
    return workers
