"""One training episode on :class:`sim.simulation.Simulation`, the evaluator's simulator, unchanged:
the same ``reset``/``step``, action decoding, events, done reasons and record rows. A session adds
what a training loop needs and evaluation does not: a terminal observation of each agent that
finished, the step's scoring terms, and observations encoded into the Gymnasium space.

A session runs either in the environment's own process (:class:`InProcessSimulator`, the default
when nothing else simulates there) or in a child process (:mod:`learn.worker`), which holds a
:class:`SimulatorSession` of its own and sends its replies back over a pipe;
:func:`learn.simulators.open_simulator` chooses. What both ends share is :mod:`learn.protocol`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from arena.scenario import load_scenario
from evaluator.scoring import load_profile
from learn.protocol import Config, Reply
from learn.record_views import RecordViews
from learn.render import TopView
from learn.terms import EpisodeTerms
from sim.observation_arrays import ObservationLayout
from sim.observation_record import ArraysObservation
from sim.simulation import Simulation
from sim.traffic import sumo_running


class SimulatorSession:
    """The simulator of one environment, episode after episode. ``packed``: observations as
    records of :class:`sim.observation_arrays.ObservationLayout` (for the pipe), else as the
    dicts of arrays."""

    def __init__(self, config: Config, *, packed: bool = False) -> None:
        self.config = config
        self.profile = load_profile(config.profile)
        self._views = RecordViews(ObservationLayout(config.interface))
        self._packed = packed
        self.sim = None
        self._view = None  # learn.render.TopView of the episode, when rendering
        self._terms = EpisodeTerms(self.profile)

    def reset(self, scenario_dir: str, seed: int | None) -> Reply:
        self._end_episode()
        folder = Path(scenario_dir)
        scenario = load_scenario(folder)
        # The simulator writes each observation straight into its arrays record.
        self.sim = Simulation(scenario, folder, self.config.interface, seed, arrays=True)
        self._terms = EpisodeTerms(self.profile)
        if self.config.render:
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
        live_before = sim.live  # in the order of sim.vehicles
        # The simulator hands an agent that finished while driving this step its last
        # observation once (``done`` True): that is the Gymnasium terminal observation.
        drove = sim.step(actions)
        reply = Reply(observations={}, scenario_id=sim.scenario.id)
        obs = {}
        rows = sim.recorder.rows
        for agent_id, observation in drove.items():
            if not observation.done:
                obs[agent_id] = observation
            reply.events[agent_id] = observation.events.as_observation()
            reply.terms[agent_id] = self._terms.step(agent_id, rows[agent_id])
        for v in live_before:
            if v.id not in obs:
                reply.finished[v.id] = str(v.reason)
                if v.id in drove:  # drove this step (not ended by an invalid action)
                    reply.terminal[v.id] = self._encode(drove[v.id])
        # Only agents still waiting to enter: move time on until one does or the episode ends.
        while not obs and not sim.done:
            obs = {k: o for k, o in sim.step({}).items() if not o.done}
        return self._reply(obs, reply)

    def _reply(self, obs: dict[str, ArraysObservation], reply: Reply) -> Reply:
        assert self.sim is not None
        reply.observations = {k: self._encode(o) for k, o in obs.items()}
        reply.ids = {
            k: {"id": k, "road_id": o.road_id, "lane_id": o.lane_id} for k, o in obs.items()
        }
        reply.done = self.sim.done
        reply.step = self.sim.step_count
        if self._view is not None and self.sim.vehicles:
            reply.picture = self._view.picture(self.sim, self.sim.vehicles[0].id)
        if reply.done:  # SUMO's one slot per process is free between episodes
            self._end_episode()
        return reply

    def _encode(self, obs: ArraysObservation) -> Any:
        # A copy: the simulator rewrites its record at the agent's next step, and a training
        # loop may keep this observation longer.
        record = bytearray(obs.record)
        return record if self._packed else self._views.arrays(record)

    def _end_episode(self) -> None:
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
        return cls._holder is None and not sumo_running()
