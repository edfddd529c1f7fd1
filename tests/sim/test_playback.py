from __future__ import annotations

from pathlib import Path

import numpy as np

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
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


def test_every_steps_states_are_the_recording_minus_the_vehicles_handed_over() -> None:
    # A table none of whose vehicles went to SUMO serves each step's states as slices of one
    # array made once; one with a vehicle handed over gathers them per step. Both must give the
    # same vehicles, order and values bit for bit, at every step and past the recording's end.
    folder = SHIPPED_PUBLIC_DIR / "p030_replay_cruise"
    scenario = load_scenario(folder)
    replayed = ReplayTable(folder / scenario.traffic.trajectories, scenario.step_length)
    gathered = replayed.fresh()
    handed = len(replayed.ids) // 2
    gathered.hand_over(handed)
    for step in range(len(replayed.motion) + 3):
        whole, rest = replayed.states(step), gathered.states(step)
        keep = np.array([i for i, vid in enumerate(whole.ids) if vid != replayed.ids[handed]])
        assert rest.ids == [whole.ids[i] for i in keep.tolist()]
        assert rest.values.tobytes() == whole.values[keep.astype(int)].tobytes()
        assert whole.lane_id == [""] * len(whole) and len(whole.values) == len(whole)
    assert replayed.states(len(replayed.motion) // 2).ids  # the recording has vehicles to compare
    assert replayed.fresh().states(1).values.tobytes() == replayed.states(1).values.tobytes()
