"""Scripted test agents. Module-level factories so that the isolated runner can pickle them."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable

from arena.errors import AgentFailed
from arena.outcome import DoneReason

Policy = Callable[[dict], list[float]]  # one agent's observation -> its action


class ScriptedAgent:
    """Applies ``policy`` to every agent's observation; keeps every observation it saw."""

    def __init__(self, policy: Policy) -> None:
        self.policy = policy
        self.seen: list[dict[str, dict]] = []
        self.closed = False

    def reset(self) -> None:
        self.seen = []

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        self.seen.append(obs)
        return {agent_id: self.policy(o) for agent_id, o in obs.items()}

    def close(self) -> None:
        self.closed = True

    def logs(self) -> str:
        return f"acted {len(self.seen)} times"


def drive_straight(speed: float) -> Policy:
    """TargetPose: keep heading and lateral position, advance ``speed`` [m/s] x 0.1 s."""

    def policy(obs: dict) -> list[float]:
        x, y, _ = obs["ego_vehicle_state"]["position"]
        heading = obs["ego_vehicle_state"]["heading"]
        return [x + speed * 0.1, y, heading, 0.1]

    return policy


def stand_still(obs: dict) -> list[float]:
    x, y, _ = obs["ego_vehicle_state"]["position"]
    return [x, y, obs["ego_vehicle_state"]["heading"], 0.1]


def cruising_agent() -> ScriptedAgent:
    return ScriptedAgent(drive_straight(10.0))


class _Crashing(ScriptedAgent):
    def act(self, obs):
        os.kill(os.getpid(), signal.SIGSEGV)  # what a segfaulting SUMO does to its process


def crashing_agent() -> ScriptedAgent:
    return _Crashing(stand_still)


def agent_that_times_out_at_init() -> ScriptedAgent:
    raise AgentFailed(DoneReason.init_timeout, "Policy() took more than 60 s")


class _Hanging(ScriptedAgent):
    def act(self, obs):
        time.sleep(3600)


def hanging_agent() -> ScriptedAgent:
    return _Hanging(stand_still)


def slow_agent() -> ScriptedAgent:
    def policy(obs):
        time.sleep(0.05)
        return drive_straight(5.0)(obs)

    return ScriptedAgent(policy)


class _PreloadReporter(ScriptedAgent):
    def __init__(self, preloaded: bool, frozen: bool) -> None:
        super().__init__(stand_still)
        self.preloaded = preloaded
        self.frozen = frozen

    def logs(self) -> str:
        return f"preloaded={self.preloaded} frozen={self.frozen}"


class PreloadProbe:
    """An agent factory naming a module for the simulator's fork server to import once; its
    agent's log says whether that module was already imported when the factory ran, and whether
    the objects inherited from the server are out of the garbage collector's reach."""

    preload_modules = ("wave",)  # stdlib, imported by nothing else here

    def __call__(self) -> ScriptedAgent:
        import gc
        import sys

        return _PreloadReporter("wave" in sys.modules, gc.get_freeze_count() > 0)


class _FailingAt(ScriptedAgent):
    """Fails in ``reset`` or ``close`` as a sandboxed agent handle does (``AgentFailed``), or as
    an in-process policy's own bug does (any exception)."""

    def __init__(self, where: str, error: BaseException) -> None:
        super().__init__(stand_still)
        self.where, self.error = where, error

    def reset(self) -> None:
        if self.where == "reset":
            raise self.error

    def close(self) -> None:
        if self.where == "close":
            raise self.error


def agent_whose_reset_times_out() -> ScriptedAgent:
    return _FailingAt("reset", AgentFailed(DoneReason.init_timeout, "no done within 60 s"))


def agent_whose_reset_exits() -> ScriptedAgent:
    return _FailingAt("reset", AgentFailed(DoneReason.agent_exited, "exited with status 3"))


def agent_whose_reset_raises() -> ScriptedAgent:
    return _FailingAt("reset", ValueError("reset broken on purpose \ud800"))


def agent_whose_close_fails() -> ScriptedAgent:
    return _FailingAt("close", AgentFailed(DoneReason.agent_exited, "died while closing"))
