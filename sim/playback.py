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
    starts: list[int]  # (steps + 1,) the first row of each step, then the total

    def span(self, step: int) -> tuple[int, int]:
        """The rows of ``step`` (none past the recording's end)."""
        starts = self.starts
        return (starts[step], starts[step + 1]) if step < len(starts) - 1 else (0, 0)


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
        self._by_step: _StepRows | None = None  # made when first asked (in the episode)
        self._lanes: list[str] | None = None  # each row's lane, made at the first states()

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
        by_step = self._by_step or self._step_rows()
        start, end = by_step.span(step)
        vehicle = by_step.vehicle[start:end]
        return vehicle[self.active[vehicle]] if self._handed_over else vehicle

    def motion_at(self, step: int, rows: np.ndarray) -> np.ndarray:
        """x, y, heading, speed (len(rows), 4) of vehicle ``rows`` at ``step``; past the
        recording's end no vehicle exists (:meth:`present` is empty), so neither does a row."""
        if step >= len(self.motion):
            return np.empty((0, 4))
        return self.motion[step].take(rows, 0)

    def states(self, step: int) -> VehicleStates:
        """The replayed (not handed over) vehicles' states at ``step``, in row order."""
        by_step = self._by_step or self._step_rows()
        lanes = self._lanes or self._row_lanes(by_step)
        start, end = by_step.span(step)
        if start == end:
            return VehicleStates.empty()
        if not self._handed_over:  # each step's states are slices of one table: no numpy
            return VehicleStates.of(
                by_step.ids[start:end], by_step.values[start:end], lanes[start:end]
            )
        rows = start + np.flatnonzero(self.active[by_step.vehicle[start:end]])
        at = rows.tolist()
        ids = by_step.ids
        return VehicleStates.of(
            [ids[k] for k in at], by_step.values.take(rows, 0), [lanes[k] for k in at]
        )

    def _step_rows(self) -> _StepRows:
        """Every (step, vehicle) the recording holds, step after step, vehicles in row order."""
        steps, vehicle = (~np.isnan(self.motion[:, :, 0])).nonzero()
        values = np.concatenate([self.motion[steps, vehicle], self.dims.take(vehicle, 0)], 1)
        values.flags.writeable = vehicle.flags.writeable = False  # every step shares them
        starts = steps.searchsorted(np.arange(len(self.motion) + 1)).tolist()
        ids = [self.ids[k] for k in vehicle.tolist()]
        self._by_step = _StepRows(values, vehicle, ids, starts)
        return self._by_step

    def _row_lanes(self, by_step: _StepRows) -> list[str]:
        """Each row's nearest lane id ("" without a road), all rows in one query."""
        if self.road is None:
            self._lanes = [""] * len(by_step.ids)
        else:
            self._lanes = [lane.id for lane in self.road.nearest_lanes(by_step.values[:, :2])]
        return self._lanes

    length = property(lambda self: self.dims[:, 0], doc="(vehicles,) [m]")
    width = property(lambda self: self.dims[:, 1], doc="(vehicles,) [m]")
