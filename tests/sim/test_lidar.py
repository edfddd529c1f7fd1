"""SMARTS's lidar (``sim/lidar.py``): rays end at the first vehicle side or road edge."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from arena.scenario import load_scenario
from sim.lidar import RANGE, RAYS, Lidar
from sim.road import RoadNetwork
from tests.sim.test_bev import PUBLIC_T_JUNCTION, states


@pytest.fixture(scope="module")
def road() -> RoadNetwork:
    scenario = load_scenario(PUBLIC_T_JUNCTION)
    return RoadNetwork.load(PUBLIC_T_JUNCTION / scenario.map)


def on_a_lane(road: RoadNetwork) -> tuple[float, float, float]:
    lane = max(
        (lane for lane in road.lanes.values() if not lane.is_internal), key=lambda la: la.length
    )
    x, y = lane.position_at(lane.length / 2)
    return float(x), float(y), float(lane.heading_at(lane.length / 2))


def test_a_car_ahead_ends_the_forward_ray_at_its_rear(road) -> None:
    x, y, heading = on_a_lane(road)
    ahead = ("car", x + 12 * math.cos(heading), y + 12 * math.sin(heading), heading)
    scan = Lidar(road).scan(x, y, heading, states(ahead))
    assert scan["points"].shape == (RAYS, 3) and scan["hits"].shape == (RAYS,)
    assert scan["hits"][0]
    forward = np.hypot(*(scan["points"][0, :2] - (x, y)))
    assert forward == pytest.approx(12 - 4.5 / 2, abs=1e-6)  # the car is 4.5 m long
    assert np.allclose(np.hypot(*(scan["ends"][:, :2] - (x, y)).T), RANGE)


def test_side_rays_end_at_the_road_edge_where_shapely_finds_it(road) -> None:
    x, y, heading = on_a_lane(road)
    scan = Lidar(road).scan(x, y, heading, states())
    boundary = road.drivable_area.boundary
    for k in (RAYS // 4, 3 * RAYS // 4):  # straight left, straight right
        angle = heading + k * 2 * math.pi / RAYS
        ray = shapely.LineString(
            [(x, y), (x + RANGE * math.cos(angle), y + RANGE * math.sin(angle))]
        )
        crossing = ray.intersection(boundary)
        if crossing.is_empty:
            assert not scan["hits"][k]
            continue
        expected = shapely.Point(x, y).distance(crossing)
        assert scan["hits"][k]
        assert np.hypot(*(scan["points"][k, :2] - (x, y))) == pytest.approx(expected, abs=1e-6)
    misses = ~scan["hits"]
    assert np.all(np.isinf(scan["points"][misses]))
