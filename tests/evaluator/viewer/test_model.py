"""The replay data model from a real episode record: every vehicle's pose per step, the agents'
speed and events, the map once."""

import json

import numpy as np
import pytest

from arena.errors import RecordError
from evaluator.scoring.record import read_arrays
from evaluator.viewer.model import VehicleKind, load_replay
from tests.evaluator.scoring.builders import AgentSpec, drive, write_record


@pytest.mark.slow
def test_mission_agents_and_every_vehicle_they_saw_step_by_step(episode):
    suite, record = episode
    arrays = read_arrays(record)
    replay = load_replay(record, suite)
    assert replay.first_step == 1 and replay.frames == int(arrays["step"].max())
    assert replay.vehicle_ids[:2] == ("Agent_0", "Agent_1")
    assert replay.kinds[:2] == (VehicleKind.ego, VehicleKind.mission)
    seen = set(arrays["nbr_id"][arrays["nbr_valid"]].tolist()) - {"Agent_0", "Agent_1"}
    assert set(replay.vehicle_ids[2:]) == seen and len(seen) >= 2
    assert set(replay.kinds[2:]) == {VehicleKind.traffic}
    for a in range(2):
        n = int(arrays["steps"][a])
        np.testing.assert_allclose(replay.x[a, :n], arrays["x"][a, :n])
        np.testing.assert_allclose(replay.heading[a, :n], arrays["heading"][a, :n])
        assert np.isnan(replay.x[a, n:]).all()  # done: no pose after its last driven step
    # A background vehicle sits where the agent that saw it says, at that step.
    a, t, k = (int(i[0]) for i in np.nonzero(arrays["nbr_id"] == "slow"))
    v = replay.vehicle_ids.index("slow")
    frame = int(arrays["step"][a, t]) - replay.first_step
    assert replay.x[v, frame] == pytest.approx(arrays["nbr_x"][a, t, k])
    assert replay.length[v] == pytest.approx(arrays["nbr_length"][a, t, k])


def test_speed_events_and_the_end_per_agent(episode):
    suite, record = episode
    arrays = read_arrays(record)
    crashed, cruised = load_replay(record, suite).agents
    first_crash = int(np.flatnonzero(arrays["ev_collision"][0])[0])
    # One event where the collision starts, not one per step it lasts.
    assert [e for e in crashed.events if e[1] == "collision"] == [(first_crash, "collision")]
    assert crashed.done_reason == "collision" and cruised.done_reason == "max_episode_steps"
    n = int(arrays["steps"][1])
    np.testing.assert_allclose(cruised.speed[:n], arrays["speed"][1, :n])
    assert cruised.goal[:2] == (float(arrays["goal_x"][1]), float(arrays["goal_y"][1]))


def test_json_holds_the_map_once_and_poses_only_where_known(episode):
    suite, record = episode
    data = json.loads(json.dumps(load_replay(record, suite).to_json()))
    assert data["frames"] == 60 and data["style"]["events"]["collision"]
    assert len(data["map"]["lanes"]) == 3 and data["map"]["solid"]
    ego = data["vehicles"][0]
    assert ego["start"] == 0 and len(ego["x"]) == 23  # up to its collision
    assert all(len(v["x"]) == len(v["y"]) == len(v["heading"]) for v in data["vehicles"])
    assert load_replay(record).to_json()["map"] is None  # no suite at hand: vehicles only


def test_a_record_without_a_driven_step_is_refused(tmp_path):
    path = write_record(tmp_path / "r.npz", "s", [AgentSpec(drive(0))])
    with pytest.raises(RecordError, match="nothing to replay"):
        load_replay(path)
