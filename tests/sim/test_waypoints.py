"""Waypoint paths on the public maps, drawn from the failures real SMARTS agents hit (issue 10):
turning junction lanes, duplicate points at lane joins, empty paths at dead ends."""

from __future__ import annotations

import json
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from sim.road import RoadNetwork
from sim.road.lane import WAYPOINT_SPACING
from sim.road.waypoints import ROAD_WAYPOINTS_HORIZON, road_waypoints, waypoint_paths

PUBLIC = Path(__file__).resolve().parents[2] / "scenarios" / "public"
SCENARIOS = sorted(p.name for p in PUBLIC.iterdir() if (p / "scenario.json").exists())


@cache
def road_of(name: str) -> RoadNetwork:
    return RoadNetwork.load(PUBLIC / name / "map.net.xml")


def mission_of(name: str, k: int = 0) -> dict:
    return json.loads((PUBLIC / name / "scenario.json").read_text())["missions"][k]


def paths_at(road: RoadNetwork, x: float, y: float, heading: float, route, n: int = 50):
    position = road.nearest_lane(x, y, heading)
    return waypoint_paths(road, position, x, y, tuple(route), 4, n)


def lanes_of(path: list[dict]) -> list[str]:
    return list(dict.fromkeys(w["lane_id"] for w in path))


@pytest.mark.parametrize(
    "name", ["p002_turn_c_left_turn_c_low", "p004_turn_c_left_turn_middle_lane_c_low"]
)
@pytest.mark.parametrize("into_junction", [1.0, 2.0, 3.0])
def test_left_turn_path_in_the_junction_takes_the_turning_lane(name, into_junction):
    """A vehicle that has just entered a cross junction on a left-turn route sits nearest to the
    straight-on junction lane; its path must still turn onto the route's outgoing road."""
    road, route = road_of(name), tuple(mission_of(name)["route"])
    incoming = road.edges[route[0]][0]
    end_x, end_y = incoming.position_at(incoming.length)
    heading = incoming.heading_end
    x = float(end_x) + into_junction * math.cos(heading)
    y = float(end_y) + into_junction * math.sin(heading)
    straight = road.nearest_lane(x, y, heading).lane
    assert straight.is_internal and road.lanes[straight.successors[0]].edge_id not in route
    (path,) = paths_at(road, x, y, heading, route)
    turn, *after = lanes_of(path)
    assert road.lanes[turn].is_internal and turn != straight.id
    assert after and road.lanes[after[0]].edge_id == route[-1]
    assert len(path) == 50


@pytest.mark.parametrize(
    "name", ["p002_turn_c_left_turn_c_low", "p004_turn_c_left_turn_middle_lane_c_low"]
)
def test_path_keeps_its_turning_lane_when_the_vehicle_enters_the_junction(name):
    """Several junction lanes turn onto the route (one per outgoing lane): the path just before
    the junction and the paths inside it take the same one, not a neighbouring turning lane."""
    road, route = road_of(name), tuple(mission_of(name)["route"])
    incoming = road.edges[route[0]][0]
    heading = incoming.heading_end
    end_x, end_y = (float(v) for v in incoming.position_at(incoming.length))
    chosen = []
    for into in (-0.3, 1.0, 2.0, 3.0):
        x, y = end_x + into * math.cos(heading), end_y + into * math.sin(heading)
        path = next(
            p
            for p in paths_at(road, x, y, heading, route)
            if p[0]["lane_id"] == incoming.id or road.lanes[p[0]["lane_id"]].is_internal
        )
        chosen.append(next(w["lane_id"] for w in path if road.lanes[w["lane_id"]].is_internal))
    assert len(set(chosen)) == 1, chosen


def _spacings(path: list[dict]) -> np.ndarray:
    xy = np.array([w["pos"] for w in path])
    return np.hypot(*np.diff(xy, axis=0).T)


@pytest.mark.parametrize("name", SCENARIOS)
def test_paths_are_evenly_spaced_across_lane_joins(name):
    """Every mission's paths from its start, along its whole route (long paths cross several lane
    and junction joins): consecutive points never closer than half the spacing, never further
    than one spacing (the chord of a 1 m arc is a little shorter)."""
    road = road_of(name)
    for k in range(len(json.loads((PUBLIC / name / "scenario.json").read_text())["missions"])):
        m = mission_of(name, k)
        x, y, heading = m["start"]
        paths = paths_at(road, x, y, heading, m["route"], n=400)
        assert paths
        for path in paths:
            gaps = _spacings(path)
            assert gaps.min() >= WAYPOINT_SPACING / 2, (lanes_of(path), gaps.argmin())
            assert gaps.max() <= WAYPOINT_SPACING + 1e-3


def test_path_through_a_lane_join_has_no_duplicate_point():
    """The junction lane ends exactly where the outgoing edge starts: the old paths listed that
    point twice (a spline through them divides by zero)."""
    road = road_of("p000_left_turn_t_low")
    lane = road.lanes[":J_0_0"]  # straight on, 14.4 m, into w_out_0
    x, y = (float(v) for v in lane.position_at(0.4))
    (path,) = paths_at(road, x, y, lane.heading_at(0.4), ("e_in", "w_out"))
    assert lanes_of(path)[:2] == [":J_0_0", "w_out_0"]
    assert _spacings(path).min() == pytest.approx(WAYPOINT_SPACING, abs=1e-3)


def test_path_at_the_end_of_an_acceleration_lane_is_not_empty():
    road = road_of("p009_merge_2lane_low")
    lane = road.lanes["merge_0"]
    assert not lane.successors  # the acceleration lane ends
    for s in (lane.length - 0.05, lane.length):  # the last point is the vehicle's own
        x, y = (float(v) for v in lane.position_at(s))
        paths = paths_at(road, x, y, lane.heading_at(s), ("ramp", "merge", "out"))
        assert all(paths)
        mine = next(p for p in paths if p[0]["lane_id"] == "merge_0")
        assert len(mine) == 1 and mine[0]["pos"] == pytest.approx(lane.position_at(s), abs=1e-3)


@pytest.mark.parametrize("fraction", [0.0, 0.25, 0.5, 0.999])
def test_the_first_waypoint_is_level_with_the_vehicle(fraction):
    """As SMARTS documents: the path starts at the vehicle's own offset along its lane (not at
    the next whole metre), and the rest follow 1 m apart from there."""
    road = road_of("p009_merge_2lane_low")
    lane = road.lanes["merge_0"]
    s = 30.0 + fraction
    x, y = (float(v) for v in lane.position_at(s))
    paths = paths_at(road, x, y, lane.heading_at(s), ("ramp", "merge", "out"))
    mine = next(p for p in paths if p[0]["lane_id"] == "merge_0")
    assert mine[0]["lane_offset"] == pytest.approx(s)
    assert mine[0]["pos"] == pytest.approx([x, y], abs=1e-3)
    assert [w["lane_offset"] for w in mine[:5]] == pytest.approx([s + k for k in range(5)])


@pytest.mark.parametrize("past_end", [0.05, 3.0])
def test_path_at_the_end_of_the_road_is_not_empty(past_end):
    road = road_of("p000_left_turn_t_low")
    lane = road.lanes["w_out_0"]
    assert not lane.successors
    end = lane.position_at(lane.length)
    x = float(end[0]) + (past_end - 0.1) * math.cos(lane.heading_end)
    y = float(end[1]) + (past_end - 0.1) * math.sin(lane.heading_end)
    paths = paths_at(road, x, y, lane.heading_end, ("s_in", "w_out"))
    assert paths and all(len(p) >= 1 for p in paths)
    assert paths[0][-1]["lane_id"].startswith("w_out")


def test_road_waypoints_cover_every_lane_of_the_road_from_behind_the_vehicle():
    """SMARTS's road_waypoints: lane id -> a path from 20 m behind the vehicle's offset on that
    lane to 20 m ahead, for each lane of its road."""
    road = road_of("p009_merge_2lane_low")
    lane = road.lanes["merge_0"]
    s = 60.0
    x, y = (float(v) for v in lane.position_at(s))
    position = road.nearest_lane(x, y, float(lane.heading_at(s)))
    lanes = road_waypoints(road, position, x, y, ("ramp", "merge", "out"))
    assert set(lanes) == {other.id for other in road.edges[lane.edge_id]}
    (path,) = lanes["merge_0"]
    horizon = ROAD_WAYPOINTS_HORIZON
    assert len(path) == 2 * horizon + 1
    assert path[0]["lane_offset"] == pytest.approx(s - horizon)
    assert _spacings(path).min() == pytest.approx(WAYPOINT_SPACING, abs=1e-3)
