"""Non-reactive replay traffic: recorded trajectories laid out as dense per-step arrays."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from sim.trajectories import read_trajectories
from sim.vehicle.states import VehicleStates


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
        shape = (len(self.ids), n_steps)
        self.x, self.y, self.heading, self.speed = (np.full(shape, np.nan) for _ in range(4))
        self.length = np.array([trajectories[v].length for v in self.ids])  # (n,) [m]
        self.width = np.array([trajectories[v].width for v in self.ids])  # (n,) [m]
        for k, v in enumerate(self.ids):
            tr = trajectories[v]
            span = slice(first[v], first[v] + len(tr.time))
            self.x[k, span], self.y[k, span] = tr.x, tr.y
            self.heading[k, span], self.speed[k, span] = tr.heading, tr.speed
        self.active = np.ones(len(self.ids), dtype=bool)  # False once handed to SUMO

    def fresh(self) -> ReplayTable:
        """This recording with every vehicle replayed again (none handed to SUMO yet), for a new
        episode; the recorded arrays are shared and never written."""
        table = copy.copy(self)
        table.active = np.ones(len(self.ids), dtype=bool)
        return table

    def present(self, step: int) -> np.ndarray:
        """Row indices of the replayed (not handed over) vehicles existing at ``step``."""
        if step >= self.x.shape[1]:
            return np.zeros(0, dtype=int)
        return np.flatnonzero(self.active & ~np.isnan(self.x[:, step]))

    def states(self, step: int) -> VehicleStates:
        rows = self.present(step)
        if not len(rows):
            # Past the end of the recording there is no column to index, not even with no rows.
            return VehicleStates.empty()
        return VehicleStates(
            [self.ids[k] for k in rows],
            self.x[rows, step],
            self.y[rows, step],
            self.heading[rows, step],
            self.speed[rows, step],
            self.length[rows],
            self.width[rows],
            [""] * len(rows),
        )
