"""One simulator in a child process, driven over a pipe by a training environment.

libsumo holds one simulation per process, so every environment owns a child of its own (started
with ``subprocess``, which also works inside the daemonic workers of ``AsyncVectorEnv``). The
child runs :class:`sim.simulation.Simulation`, the evaluator's simulator, unchanged: the same
``reset``/``step``, action decoding, events, done reasons and record rows. It additionally keeps
what a training loop needs and evaluation does not: a terminal observation of each agent that
finished, the step's scoring terms, and observations encoded into the Gymnasium space.

Frames both ways are a 4-byte big-endian length and a pickle: both ends are our own code.
"""

from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

HEADER = struct.Struct(">I")
PROJECT_ROOT = Path(__file__).resolve().parents[1]


class SimulatorError(RuntimeError):
    """The simulator child failed (a SUMO error, or the child died)."""


@dataclass(frozen=True)
class Config:
    interface: Any  # sim.interface.AgentInterface
    max_neighbours: int
    profile: str  # scoring profile whose terms go into info


@dataclass
class Reply:
    """What one reset or step produced."""

    # Observations are encoded and packed (learn.packing); SimulatorProcess unpacks them.
    observations: dict[str, Any]  # of the agents live after the step
    finished: dict[str, str] = field(default_factory=dict)  # agent id -> done reason
    terminal: dict[str, Any] = field(default_factory=dict)  # of the agents finished this step
    events: dict[str, dict] = field(default_factory=dict)  # of every agent that drove this step
    terms: dict[str, dict[str, float]] = field(default_factory=dict)
    ids: dict[str, dict[str, str]] = field(default_factory=dict)  # road/lane ids per agent
    done: bool = False  # the episode is over for everyone
    scenario_id: str = ""
    step: int = 0


# --- the parent's side -----------------------------------------------------------------------


class SimulatorProcess:
    """A child process holding one simulator; :meth:`call` sends a command and waits."""

    def __init__(self, config: Config) -> None:
        from learn.packing import Layout
        from learn.spaces import observation_space

        self._layout = Layout(observation_space(config.interface, config.max_neighbours))
        env = dict(os.environ)
        # The child must import the same code as this process (a worktree before an install).
        env["PYTHONPATH"] = os.pathsep.join(
            [str(PROJECT_ROOT), *filter(None, [env.get("PYTHONPATH")])]
        )
        self._child = subprocess.Popen(
            [sys.executable, "-m", "learn.worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
        )
        self.call("configure", config)

    def call(self, kind: str, body: Any = None) -> Any:
        if self._child.poll() is not None:
            raise SimulatorError(f"simulator process exited with code {self._child.returncode}")
        try:
            _write(self._child.stdin, (kind, body))
            status, value = _read(self._child.stdout)
        except (BrokenPipeError, EOFError, struct.error) as error:
            raise SimulatorError(f"simulator process died: {error}") from error
        if status == "error":
            raise SimulatorError(value)
        if isinstance(value, Reply):
            unpack = self._layout.unpack
            value.observations = {k: unpack(v) for k, v in value.observations.items()}
            value.terminal = {k: unpack(v) for k, v in value.terminal.items()}
        return value

    def cpu_seconds(self) -> float:
        """CPU time [s] the child has used so far (user + system; Linux ``/proc``)."""
        fields = Path(f"/proc/{self._child.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def close(self) -> None:
        if self._child.poll() is None:
            try:
                _write(self._child.stdin, ("close", None))
                self._child.stdin.close()
                self._child.wait(timeout=10)
            except (BrokenPipeError, OSError, subprocess.TimeoutExpired):
                self._child.kill()
                self._child.wait()
        for stream in (self._child.stdin, self._child.stdout):
            if stream is not None and not stream.closed:
                stream.close()


def _write(stream: BinaryIO, message: Any) -> None:
    payload = pickle.dumps(message, protocol=5)
    stream.write(HEADER.pack(len(payload)) + payload)
    stream.flush()


def _read(stream: BinaryIO) -> Any:
    header = stream.read(HEADER.size)
    if len(header) < HEADER.size:
        raise EOFError("no reply")
    (size,) = HEADER.unpack(header)
    payload = stream.read(size)
    if len(payload) < size:
        raise EOFError("truncated reply")
    return pickle.loads(payload)


# --- the child's side ------------------------------------------------------------------------


class _Episode:
    """The child's state: the configuration and the running simulation."""

    def __init__(self, config: Config) -> None:
        from evaluator.scoring import load_profile
        from learn.packing import Layout
        from learn.spaces import observation_space

        self.config = config
        self.profile = load_profile(config.profile)
        self.layout = Layout(observation_space(config.interface, config.max_neighbours))
        self.sim = None

    def reset(self, scenario_dir: str, seed: int | None) -> Reply:
        from arena.scenario import load_scenario
        from sim.simulation import Simulation

        self.close()
        folder = Path(scenario_dir)
        scenario = load_scenario(folder)
        self.sim = Simulation(scenario, folder, self.config.interface, seed)
        obs = self.sim.reset()
        reply = Reply(observations={}, scenario_id=scenario.id)
        # Agents that enter later are waited for: the episode starts with the first one live.
        while not obs and not self.sim.done:
            obs = self.sim.step({})
        return self._reply(obs, reply)

    def step(self, actions: dict[str, Any]) -> Reply:
        sim = self.sim
        assert sim is not None, "reset first"
        live_before = {v.id for v in sim.live}
        # The simulator hands an agent that finished while driving this step its last
        # observation once (``done`` True): that is the Gymnasium terminal observation.
        drove = sim.step(actions)
        obs = {k: o for k, o in drove.items() if not o["done"]}
        reply = Reply(observations={}, scenario_id=sim.scenario.id)
        for v in sim.vehicles:
            if v.id in live_before and v.id not in obs:
                reply.finished[v.id] = str(v.reason)
                if v.id in drove:  # drove this step (not ended by an invalid action)
                    reply.terminal[v.id] = self._encode(drove[v.id])
        for agent_id, observation in drove.items():
            reply.events[agent_id] = observation["events"]
            reply.terms[agent_id] = _step_terms(sim.recorder.rows[agent_id], self.profile)
        # Only agents still waiting to enter: move time on until one does or the episode ends.
        while not obs and not sim.done:
            obs = {k: o for k, o in sim.step({}).items() if not o["done"]}
        return self._reply(obs, reply)

    def _reply(self, obs: dict[str, dict], reply: Reply) -> Reply:
        assert self.sim is not None
        reply.observations = {k: self._encode(o) for k, o in obs.items()}
        reply.ids = {k: _ids(o) for k, o in obs.items()}
        reply.done = self.sim.done
        reply.step = self.sim.step_count
        return reply

    def _encode(self, obs: dict) -> bytes:
        from learn.spaces import encode_observation

        encoded = encode_observation(obs, self.config.interface, self.config.max_neighbours)
        return self.layout.pack(encoded)

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
            self.sim = None


def _ids(obs: dict) -> dict[str, str]:
    ego = obs["ego_vehicle_state"]
    return {"id": ego["id"], "road_id": ego["road_id"], "lane_id": ego["lane_id"]}


def _step_terms(rows, profile) -> dict[str, float]:
    from learn.terms import step_terms

    return step_terms(rows, profile)


def main() -> int:
    # The protocol gets private copies of stdin/stdout; fd 1 then points at stderr, so SUMO's
    # and anyone's prints cannot corrupt a frame.
    reader = os.fdopen(os.dup(0), "rb")
    writer = os.fdopen(os.dup(1), "wb")
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    episode: _Episode | None = None
    while True:
        try:
            kind, body = _read(reader)
        except EOFError:
            break
        try:
            if kind == "configure":
                episode = _Episode(body)
                result: Any = None
            elif kind == "reset":
                result = episode.reset(*body)
            elif kind == "step":
                result = episode.step(body)
            elif kind == "close":
                _write(writer, ("ok", None))
                break
            else:
                raise ValueError(f"unknown command {kind!r}")
        except Exception as error:
            _write(writer, ("error", f"{error}\n{traceback.format_exc()[-4000:]}"))
            continue
        _write(writer, ("ok", result))
    if episode is not None:
        episode.close()
    return 0


if __name__ == "__main__":
    # Run the imported module's main, so that pickled replies name `learn.worker.Reply`, not
    # `__main__.Reply`, which the parent could not load.
    from learn import worker

    sys.exit(worker.main())
