from __future__ import annotations

import numpy as np
import pytest

from scenarios.maps import TEMPLATES, build_map
from scenarios.netinfo import net_info
from sim.road import RoadNetwork
from sim.road.waypoints import waypoint_paths


@pytest.mark.slow
def test_netconvert_output_is_deterministic(tmp_path):
    a = build_map("cross_upside_rotated", tmp_path / "a")
    b = build_map("cross_upside_rotated", tmp_path / "b")
    assert a.read_bytes() == b.read_bytes()
    assert b"generated on" not in a.read_bytes()


def test_unknown_template_is_a_clear_error(tmp_path):
    with pytest.raises(KeyError, match="unknown map template"):
        build_map("moon_base", tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TEMPLATES))
def test_template_builds_with_speed_limits(name, cache_dir):
    info = net_info(build_map(name, cache_dir))
    lanes = [lane for edge in info.net.getEdges() for lane in edge.getLanes()]
    assert lanes and all(lane.getSpeed() > 0 for lane in lanes)


@pytest.mark.parametrize("name", ["t_intersection", "t_intersection_rotated"])
def test_t_intersection_minor_road_has_a_stop_sign(name, cache_dir):
    info = net_info(build_map(name, cache_dir))
    minor = info.net.getEdge("s_in").getLanes()[0]
    assert {c.getState() for c in minor.getOutgoing()} == {"s"}
    major = info.net.getEdge("w_in").getLanes()[0]
    assert "s" not in {c.getState() for c in major.getOutgoing()}


def test_cross_variants_turn_the_same_way_from_different_headings(cache_dir):
    headings = set()
    for name in ("cross", "cross_rotated", "cross_upside", "cross_upside_rotated"):
        info = net_info(build_map(name, cache_dir))
        assert info.turn("s_in", "l") is not None and info.turn("s_in", "r") is not None
        headings.add(round(info.pose("s_in", 0, 10.0)[2], 2))
    assert len(headings) == 4


def test_merge_acceleration_lane_ends_or_becomes_shoulder(cache_dir):
    plain = net_info(build_map("merge_2lane", cache_dir))
    assert not plain.net.getEdge("merge").getLanes()[0].getOutgoing()
    shoulder = net_info(build_map("merge_2lane_shoulder", cache_dir))
    assert shoulder.driving_lanes("out") == [1, 2]
    short = net_info(build_map("merge_2lane_shoulder_short", cache_dir))
    assert short.length("merge") < shoulder.length("merge") - 50.0


@pytest.mark.parametrize("lanes", [2, 3, 4])
def test_curved_highway_lanes_turn_smoothly_across_the_whole_route(lanes, cache_dir):
    """A vehicle following the waypoints of a 400 m radius curve should turn about 0.0025 rad
    per metre; a coarse shape (or centimetre coordinates) turns in kinks, steps a TargetPose
    vehicle feels as jerk spikes. The path crosses the junction between the two edges."""
    road = RoadNetwork.load(build_map(f"highway_{lanes}lane_curve", cache_dir))
    start = road.edges["in"][-1]
    route = ("in", "out")
    x, y = start.position_at(5.0)
    pos = road.nearest_lane(float(x), float(y), start.heading_at(5.0))
    (path,) = waypoint_paths(road, pos, float(x), float(y), route, 1, 2000)
    assert {w["lane_id"].rsplit("_", 1)[0] for w in path} >= {"in", "out"}
    xy = np.array([w["pos"] for w in path])
    step = np.diff(xy, axis=0)
    turn = np.abs(np.diff(np.unwrap(np.arctan2(step[:, 1], step[:, 0]))))
    assert turn.max() < 0.01, turn.argmax()
    headings = np.unwrap([w["heading"] for w in path])
    assert np.abs(np.diff(headings)).max() < 0.01


@pytest.mark.parametrize("name", ["merge_2lane", "merge_3lane_curve", "merge_4lane"])
def test_on_ramp_joins_the_acceleration_lane_without_kinks(name, cache_dir):
    """The ramp leaves and joins parallel to the road, level with the acceleration lane: a
    vehicle's path from the ramp's start to the main road's end never turns more than a
    110 m radius bend would per metre."""
    road = RoadNetwork.load(build_map(name, cache_dir))
    ramp = road.lanes["ramp_0"]
    x, y = ramp.position_at(1.0)
    pos = road.nearest_lane(float(x), float(y), ramp.heading_at(1.0))
    (path,) = waypoint_paths(road, pos, float(x), float(y), ("ramp", "merge"), 1, 2000)
    assert {w["lane_id"] for w in path} >= {"ramp_0", "merge_0"}
    xy = np.array([w["pos"] for w in path])
    step = np.diff(xy, axis=0)
    turn = np.abs(np.diff(np.unwrap(np.arctan2(step[:, 1], step[:, 0]))))
    assert turn.max() < 0.02, turn.argmax()
