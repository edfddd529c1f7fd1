"""Every built scenario honours the format: missions, goals, speed limits, step limits."""

from __future__ import annotations

import math

from arena.scenario import load_scenario
from scenarios.netinfo import net_info
from tests.scenarios.conftest import manifest


def test_every_scenario_loads_with_goals_on_the_final_route_edge(hidden_dev):
    for entry in manifest(hidden_dev)["scenarios"]:
        folder = hidden_dev / entry["id"]
        scenario = load_scenario(folder)
        assert scenario.max_episode_steps == 800
        assert scenario.agents == len(scenario.missions) == entry["agents"]
        info = net_info(folder / scenario.map)
        for m in scenario.missions:
            assert m.goal.radius >= 2.0
            assert all(info.net.hasEdge(e) for e in m.route), m.route
            gx, gy = m.goal.position
            lanes = info.net.getNeighboringLanes(gx, gy, r=2.0)
            assert any(lane.getEdge().getID() == m.route[-1] for lane, _ in lanes), entry["id"]
            # A competent driver reaches the goal well inside 800 steps: the route is short.
            sx, sy, _ = m.start
            assert math.hypot(gx - sx, gy - sy) < 900.0


def test_every_lane_has_a_speed_limit(hidden_dev):
    for entry in manifest(hidden_dev)["scenarios"][::5]:
        info = net_info(hidden_dev / entry["id"] / "map.net.xml")
        for edge in info.net.getEdges():
            for lane in edge.getLanes():
                assert 5.0 < lane.getSpeed() < 40.0


def test_multi_agent_missions_start_apart(hidden_dev):
    for entry in manifest(hidden_dev)["scenarios"]:
        if entry["agents"] < 2 or not entry["reactive"]:
            continue
        missions = load_scenario(hidden_dev / entry["id"]).missions
        starts = [m.start for m in missions]
        for i in range(len(starts)):
            for j in range(i + 1, len(starts)):
                assert math.dist(starts[i][:2], starts[j][:2]) > 3.0
