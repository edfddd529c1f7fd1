from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from arena.examples import example_dir
from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.experts import PlannerAgent, planner_interface
from scenarios.verify import verify_suite
from sim.interface import ActionSpace
from tests.scenarios.conftest import manifest


def _policy_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "planner_policy", example_dir("planner") / "policy.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def straight_path(lane_index: int, y: float, n: int = 50, limit: float = 20.0) -> list[dict]:
    return [
        {
            "pos": [float(i), y],
            "heading": 0.0,
            "lane_id": f"e_{lane_index}",
            "lane_index": lane_index,
            "lane_width": 3.2,
            "speed_limit": limit,
            "lane_offset": float(i),
        }
        for i in range(n)
    ]


def observation(speed: float, neighbours: list[dict], goal=(200.0, 0.0)) -> dict:
    return {
        "dt": 0.1,
        "step_count": 1,
        "events": {},
        "ego_vehicle_state": {
            "id": "Agent_0",
            "position": [0.0, 0.0, 0.0],
            "heading": 0.0,
            "speed": speed,
            "bounding_box": [4.5, 1.8, 1.5],
            "road_id": "e",
            "lane_id": "e_0",
            "lane_index": 0,
            "mission": {"goal": {"position": list(goal), "radius": 2.5}, "route": ["e"]},
        },
        "neighborhood_vehicle_states": neighbours,
        "waypoint_paths": [straight_path(0, 0.0), straight_path(1, 3.2)],
    }


def car(x: float, y: float, speed: float) -> dict:
    return {
        "id": f"v{x}",
        "position": [x, y, 0.0],
        "heading": 0.0,
        "speed": speed,
        "bounding_box": [4.5, 1.8, 1.5],
        "road_id": "e",
        "lane_id": "e_0",
        "lane_index": 0,
    }


def test_idm_brakes_for_a_close_stopped_car_and_accelerates_on_a_free_road():
    policy = _policy_module()
    assert policy.idm(10.0, 20.0, 1e9, 30.0) > 0.0
    assert policy.idm(10.0, 20.0, 6.0, 0.0) == pytest.approx(-policy.B_MAX)


def test_planner_moves_along_the_lane_with_target_pose():
    module = _policy_module()
    action = module.Policy().act({"Agent_0": observation(10.0, [])})["Agent_0"]
    x, y, heading, dt = action
    assert dt == pytest.approx(0.1)
    assert 0.9 < x < 1.3 and abs(y) < 1e-6 and abs(heading) < 1e-6


def test_planner_slows_behind_a_slow_leader_when_the_gap_is_closed():
    module = _policy_module()
    blocked = [car(12.0, 0.0, 2.0), car(10.0, 3.2, 10.0), car(-6.0, 3.2, 10.0)]
    x, _, _, _ = module.Policy().act({"Agent_0": observation(10.0, blocked)})["Agent_0"]
    assert x < 1.0  # braking: less than 10 m/s x 0.1 s


@pytest.mark.parametrize("offset", [-0.5, 0.5])
def test_two_vehicles_level_in_each_others_target_lane_split(offset):
    """Two agents side by side, each wanting the other's lane, must not both drop back (they
    would pace each other down to a crawl): the one behind yields, the one ahead keeps going."""
    module = _policy_module()
    beside = [car(offset, 3.2, 10.0)]
    obs = observation(10.0, beside, goal=(60.0, 3.2))
    x, _, _, _ = module.Policy().act({"Agent_0": obs})["Agent_0"]
    if offset > 0.0:
        assert x < 1.0  # the other is ahead: drop back
    else:
        assert x >= 1.0  # the other is behind: keep going


def test_planner_changes_lane_to_reach_a_goal_on_the_left():
    module = _policy_module()
    planner = module.Policy()
    obs = observation(10.0, [], goal=(60.0, 3.2))
    ys = []
    for _ in range(5):
        _x, y, _h, _ = planner.act({"Agent_0": obs})["Agent_0"]
        ys.append(y)
        obs["ego_vehicle_state"]["position"] = [0.0, y, 0.0]
    assert ys[0] > 0.0 and ys[-1] > ys[0]
    assert all(b - a <= 0.2 for a, b in itertools.pairwise(ys))


def test_path_projection_and_goal_offset_on_an_arc():
    module = _policy_module()
    radius = 100.0
    waypoints = [
        {
            "pos": [radius * math.sin(s / radius), radius * (1 - math.cos(s / radius))],
            "heading": s / radius,
            "lane_id": "e_0",
            "lane_index": 0,
            "lane_width": 3.2,
            "speed_limit": 20.0,
        }
        for s in range(50)
    ]
    path = module.Path(waypoints)
    s, lat = path.project(10.0, 2.0)
    assert s == pytest.approx(10.1, abs=0.3) and lat > 1.0
    far = 120.0  # beyond the path's end, on the same circle
    gx, gy = radius * math.sin(far / radius), radius * (1 - math.cos(far / radius))
    assert path.goal_offset(gx, gy) < 0.5
    inward = np.array([0.0, radius]) - [gx, gy]  # towards the centre: the lane on the left
    ix, iy = np.array([gx, gy]) + 3.2 * inward / np.hypot(*inward)
    assert path.goal_offset(ix, iy) == pytest.approx(3.2, abs=0.3)


def test_planner_drives_on_when_the_route_ends_before_the_road_does():
    """A route cut from a recording ends mid-map: the paths run on past its last road (onto
    ``f``). They still lead to the goal, so the planner follows them instead of braking."""
    module = _policy_module()
    obs = observation(8.0, [], goal=(40.0, 0.0))
    for path in obs["waypoint_paths"]:
        for w in path[45:]:
            w["lane_id"] = w["lane_id"].replace("e_", "f_")
    braking = (8.0 - module.B_MAX * module.DT) * module.DT  # [m] one step of hard braking
    pose = module.Policy().act({"Agent_0": obs})["Agent_0"]
    assert pose[0] > 0.8  # one step at 8 m/s or more
    # A path leaving the route before its last road is still no path to follow.
    obs["ego_vehicle_state"]["mission"]["route"] = ["e", "g"]
    pose = module.Policy().act({"Agent_0": obs})["Agent_0"]
    assert pose[0] == pytest.approx(braking)


def test_planner_agent_uses_the_interface_of_its_agent_yaml():
    assert planner_interface().action_space is ActionSpace.TargetPose
    agent = PlannerAgent()
    agent.reset()
    assert agent.act({}) == {}


@pytest.mark.slow
def test_planner_solves_at_least_90_percent_of_public_reactive_scenarios():
    suite = SHIPPED_PUBLIC_DIR
    ids = [
        e["id"] for e in manifest(suite)["scenarios"] if e["reactive"] and e["family"] != "replay"
    ]
    import shutil
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "public"
        shutil.copytree(suite, copy)
        results = verify_suite(copy, ids, jobs=2)
    solved = sum(r.solved for r in results)
    assert all(r.expert == "planner" for r in results)
    assert solved >= 0.9 * len(results), [
        (r.scenario_id, r.reason) for r in results if not r.solved
    ]
    assert np.mean([r.steps for r in results if r.solved]) < 600


@pytest.mark.slow
@pytest.mark.parametrize(
    "scenario", ["p017_cruise_3lane_curve_high", "p026_overtake_3lane_curve_slow_mid"]
)
def test_planner_drives_a_curved_highway_without_jerk_spikes(scenario, tmp_path):
    """Jerk of the humanness metric, from the episode record: a TargetPose vehicle moves exactly
    to its pose, so kinks in the lanes or in the planner's target show up in full."""
    from arena.scenario import load_scenario
    from evaluator.scoring.profile import load_profile
    from evaluator.scoring.record import load_record
    from evaluator.scoring.terms import jerk
    from sim.simulation import Simulation

    folder = SHIPPED_PUBLIC_DIR / scenario
    sim = Simulation(load_scenario(folder), folder, planner_interface())
    agent = PlannerAgent()
    agent.reset()
    obs = sim.reset()
    while not sim.done:
        obs = sim.step(agent.act(obs))
    sim.write_record(tmp_path / "record.npz")
    sim.close()
    record = load_record(tmp_path / "record.npz")
    assert all(a.reached_goal for a in record.agents), record.agents
    profile = load_profile()
    for track in record.tracks:
        per_step = jerk(track, profile)[2:]  # [m/s^3]
        assert per_step.mean() < 5.0
        assert np.percentile(per_step, 95) < 20.0
