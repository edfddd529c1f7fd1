"""Non-reactive replay traffic: recorded trajectories laid out as dense per-step arrays."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.trajectories import read_trajectories
from sim.vehicle.states import VehicleStates


@dataclass(frozen=True)
class _StepRows:
    values: np.ndarray  # (rows, 6) every present vehicle's state, step-major
    ids: list[str]  # (rows,)
    starts: list[int]  # (steps + 1,) the first row of each step, then the total


class ReplayTable:
    """Every recorded vehicle's state at every episode step, NaN where it does not exist.

    Step ``k`` is simulation time ``k * dt``; a vehicle whose recording starts later appears then
    and disappears after its last frame.
    """

    def __init__(self, path: Path, dt: float) -> None:
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
        """The replayed vehicles' states at ``step``, in row order."""
        if not self._handed_over:  # every step's rows are slices of one table: no numpy per step
            by_step = self._by_step or self._step_rows()
            start, end = by_step.starts[step : step + 2] if step < len(self.motion) else (0, 0)
            if start == end:
                return VehicleStates.empty()
            return VehicleStates.of(
                by_step.ids[start:end], by_step.values[start:end], [""] * (end - start)
            )
        rows = self.present(step)
        if not len(rows):
            # Past the end of the recording there is no column to index, not even with no rows.
            return VehicleStates.empty()
        values = np.concatenate([self.motion[step].take(rows, 0), self.dims.take(rows, 0)], 1)
        return VehicleStates.of([self.ids[k] for k in rows], values, [""] * len(rows))

    def _step_rows(self) -> _StepRows:
        """Every (step, vehicle) the recording holds, step after step, vehicles in row order: the
        same values states() would gather step by step."""
        steps, rows = (~np.isnan(self.motion[:, :, 0])).nonzero()
        values = np.concatenate([self.motion[steps, rows], self.dims.take(rows, 0)], 1)
        values.flags.writeable = False  # shared by the states of every step
        starts = steps.searchsorted(np.arange(len(self.motion) + 1)).tolist()
        ids = self.ids
        self._by_step = _StepRows(values, [ids[k] for k in rows.tolist()], starts)
        return self._by_step

    length = property(lambda self: self.dims[:, 0], doc="(vehicles,) [m]")
    width = property(lambda self: self.dims[:, 1], doc="(vehicles,) [m]")
