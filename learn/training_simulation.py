"""The evaluator's simulator with the one thing training needs that evaluation does not."""

from __future__ import annotations

from sim.events import Events
from sim.mission_vehicle import MissionVehicle
from sim.simulation import Simulation
from sim.vehicles import VehicleStates


class TrainingSimulation(Simulation):
    """:class:`Simulation` unchanged (same ``reset``/``step``), remembering each agent's
    surroundings and events of the current step, so that an agent finishing in a step still gets
    the observation of where it ended (a Gymnasium terminal observation)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.last_seen: dict[str, tuple[VehicleStates, Events]] = {}

    def _detect(self, v: MissionVehicle, near: VehicleStates, step: int) -> Events:
        events = super()._detect(v, near, step)
        self.last_seen[v.id] = (near, events)
        return events

    def terminal_observation(self, v: MissionVehicle) -> dict:
        near, events = self.last_seen[v.id]
        return self._observe(v, near, events)
