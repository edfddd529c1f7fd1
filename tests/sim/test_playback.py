from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.playback import ReplayTable
from sim.trajectories import Trajectory, write_trajectories


def recorded_vehicle(vehicle_id: str, first_time: float, frames: int) -> Trajectory:
    time = first_time + 0.1 * np.arange(frames)
    x = 10.0 * time
    return Trajectory(vehicle_id, time, x, np.zeros(frames), np.zeros(frames),
                      np.full(frames, 10.0), 4.5, 1.8)  # fmt: skip


def test_vehicles_appear_and_disappear_with_their_recording(tmp_path: Path) -> None:
    path = tmp_path / "trajectories.csv"
    write_trajectories(path, [recorded_vehicle("a", 0.0, 5), recorded_vehicle("b", 0.3, 5)])
    table = ReplayTable(path, dt=0.1)
    assert table.states(0).ids == ["a"]
    assert table.states(4).ids == ["a", "b"]
    np.testing.assert_allclose(table.states(4).x, [4.0, 4.0])
    assert table.states(7).ids == ["b"]


def test_steps_after_the_recording_ends_have_no_vehicles(tmp_path: Path) -> None:
    path = tmp_path / "trajectories.csv"
    write_trajectories(path, [recorded_vehicle("a", 0.0, 5)])
    table = ReplayTable(path, dt=0.1)
    for step in (5, 6, 800):
        states = table.states(step)
        assert len(states) == 0 and states.x.shape == (0,)
