"""Non-reactive replay traffic: recorded trajectories laid out as dense per-step arrays."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.road import RoadNetwork
from sim.trajectories import read_trajectories
from sim.vehicle.states import VehicleStates


@dataclass(frozen=True)
class _StepRows:
    values: np.ndarray  # (rows, 6) every present vehicle's state, step-major
    vehicle: np.ndarray  # (rows,) the vehicle of each row: its index in ids
    ids: list[str]  # (rows,)
    lanes: list[str]  # (rows,) the nearest lane's id, "" without a road
    starts: list[int]  # (steps + 1,) the first row of each step, then the total


class ReplayTable:
    """Every recorded vehicle's state at every episode step, NaN where it does not exist.

    Step ``k`` is simulation time ``k * dt``; a vehicle whose recording starts later appears then
    and disappears after its last frame. With ``road``, the states name each vehicle's nearest
    lane (what a neighbour observation shows), found for the whole recording in one query when
    first asked: per step, a few points at a time, the query cost more than the rest of a step's
    replay.
    """

    def __init__(self, path: Path, dt: float, road: RoadNetwork | None = None) -> None:
        self.road = road
        trajectories = read_trajectories(path)
        self.ids = sorted(trajectories)
        first = {v: round(float(tr.time[0]) / dt) for v, tr in trajectories.items()}
        n_steps = max((first[v] + len(tr.time) for v, tr in trajectories.items()), default=0)
        # Step-major, each vehicle's x, y, heading, speed at a step side by side: a step's
        # states are one gather of contiguous rows.
        self.motion = np.full((n_steps, len(self.ids), 4), np.nan)
        # length, width [m] of each vehicle
        dims = [(trajectories[v].length, trajectories[v].width) for v in self.ids]
        self.dims = np.array(dims, dtype=np.float64).reshape(len(self.ids), 2)
        for k, v in enumerate(self.ids):
            tr = trajectories[v]
            span = slice(first[v], first[v] + len(tr.time))
            self.motion[span, k] = np.stack([tr.x, tr.y, tr.heading, tr.speed], axis=1)
        self.active = np.ones(len(self.ids), dtype=bool)  # False once handed over (hand_over)
        self._handed_over = False
        self._by_step: _StepRows | None = None  # made at the first states() (in the episode)

    def fresh(self) -> ReplayTable:
        """This recording with every vehicle replayed again (none handed to SUMO yet), for a new
        episode; the recorded arrays are shared and never written."""
        table = copy.copy(self)
        table.active = np.ones(len(self.ids), dtype=bool)
        table._handed_over = False
        return table

    def hand_over(self, k: int) -> None:
        """Vehicle row ``k`` is driven by SUMO from now on: no longer replayed."""
        self.active[k] = False
        self._handed_over = True

    def present(self, step: int) -> np.ndarray:
        """Row indices of the replayed (not handed over) vehicles existing at ``step``."""
        if step >= len(self.motion):
            return np.zeros(0, dtype=int)
        return (self.active & ~np.isnan(self.motion[step, :, 0])).nonzero()[0]

    def states(self, step: int) -> VehicleStates:
        """The replayed (not handed over) vehicles' states at ``step``, in row order."""
        by_step = self._by_step or self._step_rows()
        start, end = by_step.starts[step : step + 2] if step < len(self.motion) else (0, 0)
        if start == end:
            return VehicleStates.empty()
        if not self._handed_over:  # each step's states are slices of one table: no numpy
            return VehicleStates.of(
                by_step.ids[start:end], by_step.values[start:end], by_step.lanes[start:end]
            )
        rows = start + np.flatnonzero(self.active[by_step.vehicle[start:end]])
        at = rows.tolist()
        ids, lanes = by_step.ids, by_step.lanes
        return VehicleStates.of(
            [ids[k] for k in at], by_step.values.take(rows, 0), [lanes[k] for k in at]
        )

    def _step_rows(self) -> _StepRows:
        """Every (step, vehicle) the recording holds, step after step, vehicles in row order."""
        steps, vehicle = (~np.isnan(self.motion[:, :, 0])).nonzero()
        values = np.concatenate([self.motion[steps, vehicle], self.dims.take(vehicle, 0)], 1)
        values.flags.writeable = False  # shared by the states of every step
        starts = steps.searchsorted(np.arange(len(self.motion) + 1)).tolist()
        ids = [self.ids[k] for k in vehicle.tolist()]
        if self.road is None:
            lanes = [""] * len(ids)
        else:
            lanes = [lane.id for lane in self.road.nearest_lanes(values[:, :2])]
        self._by_step = _StepRows(values, vehicle, ids, lanes, starts)
        return self._by_step

    length = property(lambda self: self.dims[:, 0], doc="(vehicles,) [m]")
    width = property(lambda self: self.dims[:, 1], doc="(vehicles,) [m]")
