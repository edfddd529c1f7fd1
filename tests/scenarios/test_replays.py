from __future__ import annotations

import numpy as np
import pytest

from arena.scenario import DataLabel, load_scenario
from scenarios.maps import build_map
from scenarios.recorded.builder import EXPERT_FILE
from scenarios.recorded.recorder import record_scene
from scenarios.traffic import Flow, Routes, driver_types
from scenarios.verify import verify_suite
from sim.geometry import boxes_overlap
from sim.trajectories import read_trajectories
from tests.scenarios.conftest import manifest


def test_recorder_saves_every_vehicle_in_our_conventions(cache_dir):
    routes = Routes(vtypes=driver_types(np.random.default_rng(0), 3))
    routes.flows.append(Flow("f", routes.route(("in", "out")), 1500.0, end=20.0))
    rec = record_scene(build_map("highway_2lane", cache_dir), routes, 1, 30.0)
    assert len(rec.trajectories) > 3
    for vid, tr in rec.trajectories.items():
        assert np.allclose(np.diff(tr.time), 0.1)
        assert np.all(np.abs(tr.heading) < 0.2)  # the road runs along +x
        moved = np.diff(tr.x)
        assert np.allclose(moved, 0.5 * (tr.speed[1:] + tr.speed[:-1]) * 0.1, atol=0.35)
        assert rec.edges[vid][0] == "in"
        # SUMO inserts a vehicle with its back at the lane start: its centre is half a length in
        # (FCD reports the front bumper, a full length in).
        assert tr.x[0] == pytest.approx(tr.length / 2, abs=0.3)


@pytest.mark.slow
def test_replays_are_recorded_and_the_removed_paths_collide_with_nothing(hidden_dev):
    replays = [e for e in manifest(hidden_dev)["scenarios"] if e["family"] == "replay"]
    assert len(replays) == 58
    for entry in replays:
        folder = hidden_dev / entry["id"]
        scenario = load_scenario(folder)
        assert scenario.label is DataLabel.recorded and scenario.traffic.label is DataLabel.recorded
        others = read_trajectories(folder / scenario.traffic.trajectories)
        experts = read_trajectories(folder / EXPERT_FILE)
        assert set(experts) == {m.agent_id for m in scenario.missions}
        for m in scenario.missions:
            path = experts[m.agent_id]
            assert np.allclose([path.x[0], path.y[0]], m.start[:2], atol=1e-3)
            assert np.allclose([path.x[-1], path.y[-1]], m.goal.position, atol=1e-3)
            assert path.time[-1] < 75.0
            for other in list(others.values()) + [e for k, e in experts.items() if k != m.agent_id]:
                t = np.intersect1d(np.round(path.time, 1), np.round(other.time, 1))
                if not len(t):
                    continue
                a = np.round((t - path.time[0]) / 0.1).astype(int)
                b = np.round((t - other.time[0]) / 0.1).astype(int)
                assert not boxes_overlap(path.corners(a), other.corners(b)).any(), entry["id"]


@pytest.mark.slow
def test_log_replay_experts_complete_every_replay(hidden_dev):
    ids = [
        e["id"]
        for e in manifest(hidden_dev)["scenarios"]
        if e["family"] == "replay" and not e["reactive"]
    ]
    results = verify_suite(hidden_dev, ids, jobs=2)
    failed = [(r.scenario_id, r.reason) for r in results if not r.solved]
    assert not failed
    assert all(r.expert == "log replay" for r in results)
