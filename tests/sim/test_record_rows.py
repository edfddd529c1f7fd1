"""The recorder's rows as learn reads them during an episode (``recorder.rows[agent_id]``): the
same values as the archive written from them at the end."""

import numpy as np

from arena.record_format import EVENT_FLAGS, NEIGHBOUR_FLOATS, STEP_FLOATS
from arena.scenario import load_scenario
from sim.interface import AgentInterface
from sim.simulation import Simulation
from tests.sim.builders import ScenarioSpec, lane_y, make_scenario, mission, vehicle_xml


def test_rows_read_back_equal_the_archive(tmp_path):
    spec = ScenarioSpec(
        missions=(mission(start=(20.0, lane_y(1), 0.0), speed=10.0),),
        vehicles=[vehicle_xml(f"v{i}", 40.0 + 15.0 * i, i % 2, 8.0) for i in range(6)],
        max_episode_steps=40,
    )
    folder = make_scenario(tmp_path / "sc", spec)
    sim = Simulation(load_scenario(folder), folder, AgentInterface(), arrays=True)
    try:
        obs = sim.reset()
        while not sim.done:
            ego = obs["Agent_0"].arrays["ego_vehicle_state"]
            x, y, _ = ego["position"].tolist()  # TargetPose: 10 m/s along the lane
            obs = sim.step({"Agent_0": [x + 1.0, y, ego["heading"].item(), 0.1]})
        sim.write_record(tmp_path / "r.npz")
    finally:
        sim.close()
    rows = sim.recorder.rows["Agent_0"]
    record = np.load(tmp_path / "r.npz")
    n = int(record["steps"][0])
    assert len(rows) == n == 40
    assert [r.step for r in rows[-3:]] == [38, 39, 40] and rows[-1] == rows[n - 1]
    assert sum(len(r.neighbours) for r in rows) == record["nbr_valid"].sum() > 0
    for t, row in enumerate(rows):
        assert row.step == record["step"][0, t] and row.lane_id == record["lane_id"][0, t]
        assert row.lane_index == record["lane_index"][0, t]
        assert row.in_junction == record["in_junction"][0, t]
        assert [getattr(row, name) for name in STEP_FLOATS] == [
            record[name][0, t] for name in STEP_FLOATS
        ]
        assert list(row.flags) == [record[name][0, t] for name in EVENT_FLAGS]
        k = len(row.neighbours)
        assert row.neighbours.ids == record["nbr_id"][0, t, :k].tolist()
        for name in NEIGHBOUR_FLOATS:
            assert np.array_equal(getattr(row.neighbours, name), record[f"nbr_{name}"][0, t, :k])
