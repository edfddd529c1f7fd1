"""One training episode on :class:`sim.simulation.Simulation`, the evaluator's simulator, unchanged:
the same ``reset``/``step``, action decoding, events, done reasons and record rows. A session adds
what a training loop needs and evaluation does not: a terminal observation of each agent that
finished, the step's scoring terms, and observations encoded into the Gymnasium space.

A session runs either in the environment's own process (:func:`open_simulator`, the default
when nothing else simulates there) or in a child process (:mod:`learn.worker`), which holds a
:class:`SimulatorSession` of its own and sends its replies back over a pipe.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

SimulatorMode = Literal["auto", "in_process", "subprocess"]
SIMULATOR_MODES = ("auto", "in_process", "subprocess")


@dataclass(frozen=True)
class Config:
    interface: Any  # sim.interface.AgentInterface
    profile: str  # scoring profile whose terms go into info
    render: bool = False  # a top-down picture with every reply (render_mode="rgb_array")


@dataclass
class Reply:
    """What one reset or step produced."""

    # Observations as arrays (learn.spaces); a child process sends their records (bytes of
    # sim.observation_arrays.ObservationLayout).
    observations: dict[str, Any]  # of the agents live after the step
    finished: dict[str, str] = field(default_factory=dict)  # agent id -> done reason
    terminal: dict[str, Any] = field(default_factory=dict)  # of the agents finished this step
    events: dict[str, dict] = field(default_factory=dict)  # of every agent that drove this step
    terms: dict[str, dict[str, float]] = field(default_factory=dict)
    ids: dict[str, dict[str, str]] = field(default_factory=dict)  # road/lane ids per agent
    done: bool = False  # the episode is over for everyone
    scenario_id: str = ""
    step: int = 0
    # Top-down RGB (learn.render) around the first mission agent, when the config renders.
    picture: Any = None


class Simulator(Protocol):
    """What an environment drives: a session here or one in a child process."""

    def reset(self, scenario_dir: str, seed: int | None) -> Reply: ...

    def step(self, actions: dict[str, Any]) -> Reply: ...

    def close(self) -> None: ...


class SimulatorSession:
    """The simulator of one environment, episode after episode. ``packed``: observations as
    records of :class:`sim.observation_arrays.ObservationLayout` (for the pipe), else as the
    dicts of arrays."""

    def __init__(self, config: Config, *, packed: bool = False) -> None:
        from evaluator.scoring import load_profile
        from sim.observation_arrays import ObservationLayout

        self.config = config
        self.profile = load_profile(config.profile)
        self._layout = ObservationLayout(config.interface)
        # One encoder per agent of the episode: each follows its agent's paths step to step.
        self._encoders: dict[str, Any] = {}
        self._packed = packed
        self.sim = None
        self._view = None  # learn.render.TopView of the episode, when rendering

    def reset(self, scenario_dir: str, seed: int | None) -> Reply:
        from arena.scenario import load_scenario
        from sim.simulation import Simulation

        self._end_episode()
        folder = Path(scenario_dir)
        scenario = load_scenario(folder)
        self.sim = Simulation(scenario, folder, self.config.interface, seed)
        if self.config.render:
            from learn.render import TopView

            self._view = TopView(self.sim)
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
                    reply.terminal[v.id] = self._encode(v.id, drove[v.id])
        for agent_id, observation in drove.items():
            reply.events[agent_id] = observation["events"]
            reply.terms[agent_id] = _step_terms(sim.recorder.rows[agent_id], self.profile)
        # Only agents still waiting to enter: move time on until one does or the episode ends.
        while not obs and not sim.done:
            obs = {k: o for k, o in sim.step({}).items() if not o["done"]}
        return self._reply(obs, reply)

    def _reply(self, obs: dict[str, dict], reply: Reply) -> Reply:
        assert self.sim is not None
        reply.observations = {k: self._encode(k, o) for k, o in obs.items()}
        reply.ids = {k: _ids(o) for k, o in obs.items()}
        reply.done = self.sim.done
        reply.step = self.sim.step_count
        if self._view is not None and self.sim.vehicles:
            reply.picture = self._view.picture(self.sim, self.sim.vehicles[0].id)
        if reply.done:  # SUMO's one slot per process is free between episodes
            self._end_episode()
        return reply

    def _encode(self, agent_id: str, obs: dict) -> Any:
        from sim.observation_arrays import ObservationEncoder

        encoder = self._encoders.get(agent_id)
        if encoder is None:
            encoder = self._encoders[agent_id] = ObservationEncoder(self._layout)
        if not self._packed:
            return encoder.encode(obs)
        record = bytearray(self._layout.size)
        encoder.write(obs, record)
        return record

    def _end_episode(self) -> None:
        self._encoders.clear()
        self._view = None
        if self.sim is not None:
            self.sim.close()
            self.sim = None

    def close(self) -> None:
        self._end_episode()


class InProcessSimulator(SimulatorSession):
    """A session in this process. It holds the process's one SUMO slot from creation to
    :meth:`close` (between episodes too), so that no second environment here takes it."""

    _holder: InProcessSimulator | None = None

    def __init__(self, config: Config) -> None:
        super().__init__(config)
        InProcessSimulator._holder = self

    def close(self) -> None:
        super().close()
        if InProcessSimulator._holder is self:
            InProcessSimulator._holder = None

    @classmethod
    def slot_free(cls) -> bool:
        from sim.traffic import sumo_running

        return cls._holder is None and not sumo_running()


def open_simulator(config: Config, mode: SimulatorMode) -> Simulator:
    """The simulator for one environment. ``auto``: in this process when nothing else simulates
    here (no IPC or copying per step), else in a child process of its own."""
    from learn.worker import SimulatorProcess

    check_simulator_mode(mode)
    if mode == "subprocess" or (mode == "auto" and not InProcessSimulator.slot_free()):
        return SimulatorProcess(config)
    if not InProcessSimulator.slot_free():
        raise RuntimeError(
            "simulator='in_process': this process already runs a simulation (libsumo allows one"
            " per process); close it, or use simulator='subprocess'"
        )
    return InProcessSimulator(config)


def check_simulator_mode(mode: str) -> None:
    if mode not in SIMULATOR_MODES:
        raise ValueError(f"simulator is one of {', '.join(SIMULATOR_MODES)}, not {mode!r}")


def _ids(obs: dict) -> dict[str, str]:
    ego = obs["ego_vehicle_state"]
    return {"id": ego["id"], "road_id": ego["road_id"], "lane_id": ego["lane_id"]}


def _step_terms(rows, profile) -> dict[str, float]:
    from learn.terms import step_terms

    return step_terms(rows, profile)
