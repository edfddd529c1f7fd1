"""Run an episode in a fresh child process, so that SUMO (one simulation per process, and able to
crash) can never take down or leak state into the caller.

The parent never imports libsumo. A crash of the child (segfault, SUMO exception, kill, timeout)
becomes an :class:`EpisodeResult` with ``simulator_error`` set: it is our fault, not the
participant's, and never raises here.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib.machinery import ModuleSpec
from multiprocessing.reduction import DupFd
from pathlib import Path

from arena.errors import AgentFailed
from arena.outcome import AgentOutcome, DoneReason
from arena.scenario import load_scenario
from sim.agent import Agent
from sim.interface import AgentInterface
from sim.result import EpisodeResult

# Modules the fork server loads once, so each episode's child starts warm: this module (the
# child's entry point) and multiprocessing's own for unpickling its descriptors included. Importing
# libsumo starts nothing: only the child's own Simulation does.
_PRELOAD = [
    "sim.isolation",
    "sim.episode",
    "sim.simulation",
    "sim.inputs",
    "sumolib",
    "libsumo",
    "multiprocessing.popen_forkserver",
]
# Imported after all the others (see the module).
_FREEZE = "sim.forked"
# Held while a child starts without the main script (see _start_without_main).
_MAIN_LOCK = threading.Lock()
# The child stops the agent this long before the hard timeout, to still write the record.
_GRACE_S = 20.0


def run_episode_isolated(
    scenario_dir: Path,
    agent_factory: Callable[[], Agent],
    interface: AgentInterface,
    *,
    record_path: Path,
    seed: int | None = None,
    timeout_s: float = 900,
    episode_timeout_s: float | None = None,
) -> EpisodeResult:
    """:func:`sim.episode.run_episode` in a child process.

    ``agent_factory`` must be picklable (a module-level function or ``functools.partial``); it is
    called in the child. If it raises :class:`AgentFailed`, every agent fails with that reason
    after 0 steps (the record is still written). The child closes the agent and, when the agent
    has a ``logs()`` method, returns its text in ``extra["agent_log"]`` (and a ``stack`` dict,
    the libraries it reported, in ``extra["agent_stack"]``), and the CPU its acts
    used when it has an ``episode_cpu_s`` attribute. The episode itself
    stops at ``episode_timeout_s``, the organisers' limit (reason ``episode_timeout``, record kept);
    ``timeout_s`` is the hard limit after which the child is killed (``simulator_error``).
    The scenario's network and recording are parsed here, once per process, and reach the child
    pickled in a memory file (:mod:`sim.inputs`).
    """
    # deferred: only the episode's child process (forked from the server that preloads it) simulates
    from sim.inputs import packed_inputs

    started = time.monotonic()
    inputs = packed_inputs.open(Path(scenario_dir))
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(preload_modules(agent_factory))
    receiver, sender = ctx.Pipe(duplex=False)
    child = ctx.Process(
        target=_child_main,
        args=(Path(scenario_dir), agent_factory, interface, Path(record_path), seed),
        kwargs={
            "wall_timeout_s": wall_timeout(timeout_s, episode_timeout_s),
            "conn": sender,
            "inputs": None if inputs is None else _ChildDescriptor(inputs),
        },
        name=f"episode-{Path(scenario_dir).name}",
    )
    try:
        start_without_main(child, agent_factory)
    finally:
        sender.close()
        if inputs is not None:
            os.close(inputs)  # the child has its own now
    message = None
    try:
        if receiver.poll(timeout_s):
            message = receiver.recv()
    except (EOFError, OSError):
        message = None  # the child died without answering
    finally:
        receiver.close()
        if not isinstance(message, EpisodeResult):
            _reap(child)
    if isinstance(message, EpisodeResult):
        # The child has sent everything and only exits now: no need to wait for it (a few ms).
        threading.Thread(target=_reap, args=(child,), name=f"reap-{child.name}").start()
        return message
    if message is None:
        elapsed = time.monotonic() - started
        if elapsed >= timeout_s:
            error = f"episode process exceeded {timeout_s:.0f} s and was killed"
        else:
            error = f"episode process died (exit code {child.exitcode})"
        return failed_result(scenario_dir, error, "", elapsed)
    error, detail = message
    return failed_result(scenario_dir, error, detail, time.monotonic() - started)


def preload_modules(agent_factory: Callable[[], Agent]) -> list[str]:
    """What the fork server imports once: the simulator, the module defining ``agent_factory``
    (each child unpickles it) and the modules it lists in an optional ``preload_modules``
    attribute (what it imports when called, e.g. a sandbox client), then :mod:`sim.forked`.
    Children are forked from the server, so these imports cost once per server instead of once
    per episode (about 0.1 s with the Docker client); no episode's state reaches another, each
    child starts from the server's.

    Only the first episode of a process starts the fork server: later factories' modules are then
    imported by their children as before (slower, not different)."""
    factory_module = getattr(agent_factory, "__module__", None)
    modules = [*_PRELOAD]
    if factory_module and factory_module != "__main__":
        modules.append(factory_module)
    modules += [m for m in getattr(agent_factory, "preload_modules", ()) if m not in modules]
    return [*modules, _FREEZE]


def start_without_main(child: mp.process.BaseProcess, agent_factory) -> None:
    """Start ``child`` without running the main script again in it.

    multiprocessing runs the parent's main script in every child (as ``__mp_main__``) so that
    objects pickled from ``__main__`` resolve; for the ``arena`` command that is importing
    arena_command and every command's modules, about 0.3 s per episode of `arena evaluate` and of
    the worker. (The fork server's ``__main__`` preload that should avoid it does not work on Python
    3.11: it looks the main path up under the wrong key.) Nothing of the episode comes from
    ``__main__`` unless the factory does, so the main module is marked as a module named
    ``__main__``, which multiprocessing leaves alone, while the child starts."""
    main = sys.modules["__main__"]
    factory = getattr(agent_factory, "func", agent_factory)  # a functools.partial's function
    if getattr(factory, "__module__", None) == "__main__" or main.__dict__.get("__spec__"):
        child.start()
        return
    with _MAIN_LOCK:
        main.__spec__ = ModuleSpec("__main__", None)
        try:
            child.start()
        finally:
            main.__spec__ = None


@dataclass(frozen=True)
class _ChildDescriptor:
    """A file descriptor to hand to the child being started: unpickled there as the child's
    own descriptor of the same file (multiprocessing passes it along, as it does sockets)."""

    fd: int

    def __reduce__(self):
        return (_own_descriptor, (DupFd(self.fd),))


def _own_descriptor(passed) -> int:
    return passed.detach()


def _reap(child: mp.process.BaseProcess) -> None:
    child.join(timeout=5)
    if child.is_alive():
        child.kill()
        child.join()


def wall_timeout(timeout_s: float, episode_timeout_s: float | None) -> float:
    """The episode's own wall limit: inside the hard limit, leaving time to write the record."""
    inside_hard_limit = max(timeout_s - _GRACE_S, 0.8 * timeout_s)
    if episode_timeout_s is None:
        return inside_hard_limit
    return min(episode_timeout_s, inside_hard_limit)


def _child_main(
    scenario_dir, agent_factory, interface, record_path, seed, *, wall_timeout_s, conn, inputs
):
    try:
        conn.send(
            episode_in_this_process(
                scenario_dir,
                agent_factory,
                interface,
                record_path,
                seed,
                wall_timeout_s=wall_timeout_s,
                inputs_fd=inputs,
            )
        )
    finally:
        conn.close()


def episode_in_this_process(
    scenario_dir,
    agent_factory,
    interface,
    record_path,
    seed,
    *,
    wall_timeout_s: float,
    inputs_fd: int | None = None,
    parsed=None,
) -> EpisodeResult | tuple[str, str]:
    """The episode in an episode process: its result, or (error, detail) when the simulator
    failed. Its inputs are ``parsed`` or read from memory file ``inputs_fd`` (:mod:`sim.inputs`),
    else parsed by the simulation."""
    # deferred: only the episode's process (forked from the server that preloads it) simulates
    from sim.episode import describe_exception, run_episode
    from sim.inputs import read_inputs

    try:
        if inputs_fd is not None:
            parsed = read_inputs(inputs_fd)
        try:
            agent = agent_factory()
        except AgentFailed as exc:
            return _write_failed_start(scenario_dir, interface, record_path, seed, exc, parsed)
        result = run_episode(
            scenario_dir,
            agent,
            interface,
            record_path=record_path,
            seed=seed,
            wall_timeout_s=wall_timeout_s,
            inputs=parsed,
        )
        log = _close_agent(agent)
        if log is not None:
            result.extra["agent_log"] = log
        stack = getattr(agent, "stack", None)  # a sandboxed handle's reported libraries
        if isinstance(stack, dict):
            result.extra["agent_stack"] = stack
        return dataclasses.replace(result, agent_cpu_s=_agent_cpu_s(agent))
    except BaseException as exc:
        return f"{type(exc).__name__}: {exc}", describe_exception(exc)


def _close_agent(agent: Agent) -> str | None:
    # Closed first: a sandbox's log is complete once the agent has ended (read before, a line
    # the agent wrote just before its last answer could still be in the pipe).
    failed = None
    try:
        agent.close()
    except AgentFailed as exc:  # the episode is recorded; its agent's last failure is told
        failed = f"closing the agent: {exc.reason.value}: {exc.detail or exc}"
    logs = getattr(agent, "logs", None)
    text = logs() if callable(logs) else None
    if failed is None:
        return text
    return f"{text}\n{failed}" if text else failed


def _agent_cpu_s(agent: Agent) -> float:
    """The CPU time the agent used, from its loading, when it measures it (the evaluator's
    sandboxed handle does, an in-process test policy does not)."""
    used = getattr(agent, "episode_cpu_s", 0.0)
    return float(used) if isinstance(used, int | float) else 0.0


def _write_failed_start(scenario_dir, interface, record_path, seed, exc: AgentFailed, inputs):
    """The agent never started: every mission fails with its reason, 0 steps, empty record."""
    # deferred: only the episode's child process (forked from the server that preloads it) simulates
    from sim.simulation import Simulation

    scenario = load_scenario(scenario_dir)
    sim = Simulation(scenario, scenario_dir, interface, seed, inputs=inputs)
    sim.fail(exc.reason)
    sim.write_record(record_path)
    return EpisodeResult(
        scenario_id=scenario.id,
        steps=0,
        agents=sim.outcomes,
        record_path=str(record_path),
        detail=exc.detail or str(exc),
        agent_cpu_s=exc.cpu_s,
        observed=False,
    )


def failed_result(scenario_dir: Path, error: str, detail: str, elapsed: float) -> EpisodeResult:
    try:
        scenario = load_scenario(scenario_dir)
        scenario_id, agent_ids = scenario.id, [m.agent_id for m in scenario.missions]
    except (OSError, ValueError):
        scenario_id, agent_ids = Path(scenario_dir).name, []
    return EpisodeResult(
        scenario_id=scenario_id,
        steps=0,
        agents=tuple(
            AgentOutcome(
                id=a, reached_goal=False, reason=DoneReason.simulator_error, steps=0, done_step=0
            )
            for a in agent_ids
        ),
        record_path=None,
        simulator_error=error,
        detail=detail,
        wall_time_s=elapsed,
    )
