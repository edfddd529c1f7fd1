import math

import numpy as np
import pytest
import shapely

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.observation import neighbour_lanes
from sim.playback import ReplayTable
from sim.road import RoadNetwork
from sim.road.centrelines import CentrelineTable
from sim.road.lane import Lane
from sim.road.network import _GRID_BATCH, _well_inside
from sim.road.waypoints import split_paths, waypoint_paths
from sim.vehicle.states import VehicleStates
from tests.sim.builders import LANE_WIDTH, build_net, lane_y, straight_road


@pytest.fixture(scope="module")
def road(tmp_path_factory) -> RoadNetwork:
    return RoadNetwork.load(straight_road(tmp_path_factory.mktemp("road")))


def test_lanes_have_shape_width_speed_and_direction(road):
    east = road.lanes["E_1"]
    assert east.edge_id == "E" and east.index == 1 and not east.is_internal
    assert east.width == pytest.approx(LANE_WIDTH) and east.speed_limit == pytest.approx(13.89)
    assert east.centreline[:, 1] == pytest.approx(lane_y(1))
    assert east.heading_start == pytest.approx(0.0)
    assert road.lanes["W_0"].heading_start == pytest.approx(math.pi)


def test_nearest_lane_gives_lane_coordinates(road):
    pos = road.nearest_lane(100.0, lane_y(1) + 0.7, 0.0)
    assert pos.lane.id == "E_1"
    assert pos.t == pytest.approx(0.7)  # left of the centreline is positive
    assert pos.s == pytest.approx(100.0 - road.lanes["E_1"].centreline[0, 0])
    assert road.nearest_lane(100.0, 1.0, 0.0).lane.id == "W_0"
    lanes = road.nearest_lanes(np.array([[50.0, lane_y(0)], [60.0, 1.6]]))
    assert [lane.id for lane in lanes] == ["E_0", "W_0"]


def test_drivable_area_covers_lanes_only(road):
    assert road.is_on_road(100.0, lane_y(0) - 1.5)
    assert not road.is_on_road(100.0, lane_y(0) - 1.7)
    assert not road.is_on_road(100.0, 20.0)


def test_waypoint_paths_follow_each_lane_ahead(road):
    pos = road.nearest_lane(100.3, lane_y(1), 0.0)
    paths = waypoint_paths(road, pos, 100.3, lane_y(1), ("E",), 4, 50)
    assert [p[0]["lane_id"] for p in paths] == ["E_0", "E_1"]
    for path in paths:
        assert len(path) == 50
        xs = np.array([w["pos"][0] for w in path])
        assert np.diff(xs) == pytest.approx(1.0)
        assert 100.3 <= xs[0] <= 101.3


def test_junction_lanes_and_areas(tmp_path):
    # A T-junction: the internal lanes join the arms, and the junction polygon is not a lane.
    net = build_net(
        tmp_path,
        [("a", -100.0, 0.0), ("c", 0.0, 0.0), ("b", 100.0, 0.0), ("s", 0.0, -100.0)],
        [
            {"id": "in", "from": "a", "to": "c", "numLanes": 1},
            {"id": "out", "from": "c", "to": "b", "numLanes": 1},
            {"id": "down", "from": "c", "to": "s", "numLanes": 1},
        ],
    )
    road = RoadNetwork.load(net)
    assert road.junction_polygons
    internal = [lane for lane in road.lanes.values() if lane.is_internal]
    assert internal
    assert road.in_junction(0.0, -2.0)
    successors = {road.lanes[s].successors[0] for s in road.lanes["in_0"].successors}
    assert successors == {"out_0", "down_0"}


# A junction, curved lanes with a merge, and an urban replay's recorded-road network.
MAPS = ["p000_left_turn_t_low", "p012_merge_3lane_curve_mid_2agents", "p038_replay_urban"]


def shipped_road(scenario_id: str) -> RoadNetwork:
    folder = SHIPPED_PUBLIC_DIR / scenario_id
    return RoadNetwork.load(folder / load_scenario(folder).map)


def beside(lane: Lane, s: np.ndarray, offset: np.ndarray) -> tuple[np.ndarray, ...]:
    """Points ``offset`` [m] left of ``lane``'s centreline at ``s`` [m] along it (clamped to the
    lane), and the lane's heading there: x, y, heading."""
    base = lane.position_at(s)
    heading = np.asarray(lane.heading_at(np.clip(s, 0.0, lane.length)))
    return base[:, 0] - offset * np.sin(heading), base[:, 1] + offset * np.cos(heading), heading


@pytest.mark.parametrize("scenario_id", MAPS)
def test_area_tests_given_the_nearest_lane_agree_with_the_polygons(scenario_id):
    # The lane shortcut of is_on_road must never contradict the drivable-area polygon, also at
    # lane edges, lane ends, curves and junctions: points scattered around every lane.
    road = shipped_road(scenario_id)
    rng = np.random.default_rng(5)
    shortcut = 0
    for lane in road.lanes.values():
        s = rng.uniform(-2.0, lane.length + 2.0, 40)
        xs, ys, heading = beside(lane, s, rng.uniform(-0.7, 0.7, 40) * lane.width)
        for x, y, h in zip(xs.tolist(), ys.tolist(), heading.tolist(), strict=True):
            near = road.nearest_lane(x, y, h)
            assert road.is_on_road(x, y, near) == road.is_on_road(x, y), (lane.id, x, y)
            assert road.in_junction(x, y, near) == road.in_junction(x, y), (lane.id, x, y)
            shortcut += _well_inside(near)
    assert shortcut > 0.3 * 40 * len(road.lanes)  # the shortcut is the common case


@pytest.mark.parametrize(
    "scenario_id", ["p000_left_turn_t_low", "p012_merge_3lane_curve_mid_2agents"]
)
def test_a_single_lane_point_is_np_interp_bit_for_bit(scenario_id):
    # point_at redoes np.interp's arithmetic on floats: any other rounding would move the
    # controllers' aim point and so every record. Offsets at vertices, between them, at and past
    # both ends, and on a lane with a zero-length segment (a repeated vertex).
    lanes = list(shipped_road(scenario_id).lanes.values())
    lanes.append(Lane("dup_0", "dup", 0, np.array([[0, 0], [3, 1], [3, 1], [7.5, -2]]), 3.2, 13.9,
                      is_internal=False, is_shoulder=False))  # fmt: skip
    rng = np.random.default_rng(11)
    checked = 0
    for lane in lanes:
        cum = lane.cumulative_s
        offsets = [*cum.tolist(), -1.0, -0.0, lane.length + 0.5, *rng.uniform(0, lane.length, 30)]
        for s in offsets:
            clamped = min(max(s, 0.0), lane.length)
            expected = (
                np.interp(clamped, cum, lane.centreline[:, 0]),
                np.interp(clamped, cum, lane.centreline[:, 1]),
            )
            x, y = lane.point_at(s)
            assert type(x) is float and type(y) is float
            assert np.array([x, y]).tobytes() == np.array(expected).tobytes(), (lane.id, s)
            checked += 1
    assert checked > 30 * len(lanes)


def test_each_index_segment_knows_its_own_clearance_from_the_junctions():
    # in_junction skips the polygon test for a point on a segment farther from every junction
    # than the point is from the segment: each segment's clearance, measured for all at once,
    # must be that segment's own.
    road = shipped_road("p000_left_turn_t_low")
    clearances = road._seg_clearance
    assert len(clearances) == len(road._seg_p0) and min(clearances) == 0.0 < max(clearances)
    for k in range(0, len(clearances), 7):
        (x0, y0), (dx, dy) = road._seg_p0[k].tolist(), road._seg_d[k].tolist()
        piece = shapely.LineString([(x0, y0), (x0 + dx, y0 + dy)])
        assert clearances[k] == shapely.distance(road._junction_area, piece), k


@pytest.mark.parametrize("scenario_id", MAPS)
def test_many_points_get_the_lanes_the_search_tree_gives_one_by_one(scenario_id):
    # A large batch is answered from the grid, the tree deciding only near-ties: the lanes must
    # be the tree's own, also for points exactly between two lanes (a tie the tree breaks), on
    # lane ends, in junctions and far off the road.
    road = shipped_road(scenario_id)
    rng = np.random.default_rng(8)
    points = []
    for lane in road.lanes.values():
        s = rng.uniform(-3.0, lane.length + 3.0, 30)
        offset = rng.uniform(-4.0, 4.0, 30) * lane.width  # up to a few lanes away
        offset[::3] = lane.width / 2  # on the line between this lane and the next
        xs, ys, _ = beside(lane, s, offset)
        points.append(np.stack([xs, ys], axis=1))
    xmin, ymin, xmax, ymax = road.bounds
    points.append(rng.uniform([xmin - 30, ymin - 30], [xmax + 30, ymax + 30], (300, 2)))
    xy = np.concatenate(points)
    assert len(xy) >= _GRID_BATCH
    one_by_one = [road.nearest_lanes(xy[k : k + 1])[0] for k in range(len(xy))]
    assert road.nearest_lanes(xy) == one_by_one


def test_replayed_vehicles_name_the_lane_a_neighbour_observation_would():
    folder = SHIPPED_PUBLIC_DIR / "p030_replay_cruise"
    scenario = load_scenario(folder)
    road = RoadNetwork.load(folder / scenario.map)
    table = ReplayTable(folder / scenario.traffic.trajectories, scenario.step_length, road)
    named = 0
    for step in range(0, len(table.motion), 5):
        states = table.states(step)
        unnamed = VehicleStates.of(states.ids, states.values, [""] * len(states))
        assert states.lane_id == [lane.id for lane in neighbour_lanes(unnamed, road)]
        named += len(states)
    assert named > 100


@pytest.mark.parametrize(
    "scenario_id",
    ["p012_merge_3lane_curve_mid_2agents", "p017_cruise_3lane_curve_high", "p032_replay_merge"],
)
def test_projecting_onto_a_long_lane_through_its_grid_is_the_full_search(scenario_id):
    # A long lane answers from the segments of the point's grid cell when the nearest is near
    # enough: the same segment (first of equals), s, t and heading as the search over all
    # segments, on the centreline, at its vertices (two segments equally near), beside it and
    # far from it.
    road = shipped_road(scenario_id)
    long_lanes = [lane for lane in road.lanes.values() if len(lane.centreline) > 16]
    assert long_lanes
    rng = np.random.default_rng(4)
    for lane in long_lanes:
        s = np.concatenate([lane.cumulative_s, rng.uniform(-5.0, lane.length + 5.0, 60)])
        offset = rng.uniform(-8.0, 8.0, len(s))
        offset[: len(lane.cumulative_s)] = 0.0  # the vertices themselves
        xs, ys, _ = beside(lane, s, offset)
        for x, y in zip(xs.tolist(), ys.tolist(), strict=True):
            assert lane.project(x, y) == lane._project_vectorised(x, y), (lane.id, x, y)


def waypoints_from(lane: Lane, first_s: float, limit: int) -> tuple[list[dict], int]:
    """Up to ``limit`` of ``lane``'s waypoint dicts from ``first_s`` on, sampled and made as an
    observation's are, and how many the lane has from there."""
    total = lane.waypoint_count(first_s)
    count = min(limit, total)
    (path,) = split_paths(CentrelineTable((lane,)).sample([(lane, first_s, count)], [count]))
    return path, total


def test_waypoint_dicts_of_a_curved_lane():
    # Every waypoint sits on the centreline at its own s, rounded to 0.1 mm, with the heading of
    # the segment under it; paths starting anywhere (and at another phase) are slices of it.
    t = np.linspace(0.0, 1.0, 60)
    centreline = np.stack([400.0 * t, 80.0 * np.sin(3.0 * t)], 1)
    lane = Lane("L_0", "L", 0, centreline, 3.2, 13.9, is_internal=False, is_shoulder=False)
    points, count = waypoints_from(lane, 0.0, 10_000)
    assert len(points) == count == math.ceil(lane.length)
    for k in (0, 1, 17, 250, len(points) - 1):
        x, y = lane.position_at(float(k))
        assert points[k] == {
            "pos": [round(float(x), 4), round(float(y), 4)],
            "heading": float(lane.heading_at(float(k))),
            "lane_id": "L_0",
            "lane_index": 0,
            "lane_width": 3.2,
            "speed_limit": 13.9,
            "lane_offset": float(k),
        }
        assert all(type(v) is float for v in (*points[k]["pos"], points[k]["heading"]))
    assert waypoints_from(lane, 17.0, 50) == (points[17:67], len(points) - 17)
    shifted, count = waypoints_from(lane, 17.37, 50)
    assert [w["lane_offset"] for w in shifted] == pytest.approx([17.37 + i for i in range(50)])
    assert count == math.ceil(lane.length - 17.37)
