"""BEV rasters: orientation, colours, agreement with the lane polygons, determinism."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from arena.scenario import load_scenario
from sim.bev import COLOURS, OCCUPIED, BevRenderer, EgoPose
from sim.interface import ActionSpace, AgentInterface
from sim.road import RoadNetwork
from sim.simulation import Simulation
from sim.vehicle.states import VehicleStates
from tests.sim.builders import ScenarioSpec, lane_y, make_scenario, mission, vehicle_xml

ALL_RASTERS = {"top_down_rgb": True, "occupancy_grid_map": True, "drivable_area_grid_map": True}
PUBLIC_T_JUNCTION = Path(__file__).parents[2] / "scenarios/public/p000_left_turn_t_low"


def interface(**kwargs) -> AgentInterface:
    return AgentInterface(
        action_space=ActionSpace.LaneWithContinuousSpeed, **{**ALL_RASTERS, **kwargs}
    )


def states(*vehicles: tuple[str, float, float, float]) -> VehicleStates:
    """Cars (id, x, y, heading) 4.5 m x 1.8 m."""
    n = len(vehicles)
    return VehicleStates(
        [v[0] for v in vehicles],
        np.array([v[1] for v in vehicles], float),
        np.array([v[2] for v in vehicles], float),
        np.array([v[3] for v in vehicles], float),
        np.zeros(n),
        np.full(n, 4.5),
        np.full(n, 1.8),
        [""] * n,
    )


def pixel_world_points(ego: EgoPose, pixels: int, res: float) -> np.ndarray:
    """World position (pixels, pixels, 2) [m] of each image pixel's centre, by the documented
    convention (heading-up, ego at the centre, its left to the image's left)."""
    rows, cols = np.mgrid[0:pixels, 0:pixels].astype(float)
    forward, left = (pixels / 2 - rows) / res, (pixels / 2 - cols) / res
    c, s = math.cos(ego.heading), math.sin(ego.heading)
    return np.stack([ego.x + forward * c - left * s, ego.y + forward * s + left * c], -1)


@pytest.fixture(scope="module")
def junction_road() -> RoadNetwork:
    scenario = load_scenario(PUBLIC_T_JUNCTION)
    return RoadNetwork.load(PUBLIC_T_JUNCTION / scenario.map)


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5, math.pi / 2])
def test_a_vehicle_ahead_appears_ahead(junction_road, heading) -> None:
    bev = BevRenderer(junction_road, interface(), {"Agent_0": ()})
    ego = EgoPose(0.0, -60.0, heading, 4.5, 1.8)
    ahead = ("car", 12 * math.cos(heading), -60 + 12 * math.sin(heading), heading)
    images = bev.render("Agent_0", ego, states(ahead))
    grid, rgb = images["occupancy_grid_map"], images["top_down_rgb"]
    half, px_ahead = 128, round(12 * bev.res)  # 4 px/m by default
    assert grid[half - px_ahead, half] == OCCUPIED  # straight up the image
    assert grid[half + px_ahead, half] == 0  # nothing behind
    assert grid[half - px_ahead, half - 12] == 0  # 3 m to the left: beside the car
    assert tuple(rgb[half - px_ahead, half]) == COLOURS["vehicle"]
    assert tuple(rgb[half, half]) == COLOURS["ego"]
    occupied_rows = np.flatnonzero(grid.any(1))
    # The car (4.5 m long) spans 18 rows centred 48 rows up; the ego the centre rows.
    assert set(range(half - px_ahead - 8, half - px_ahead + 8)) <= set(occupied_rows)


def test_a_vehicle_to_the_left_appears_left_and_mission_agents_have_their_colour(
    junction_road,
) -> None:
    bev = BevRenderer(junction_road, interface(), {"Agent_0": (), "Agent_1": ()})
    ego = EgoPose(10.0, 5.0, math.pi / 2, 4.5, 1.8)  # facing +y: its left is -x
    rgb = bev.render("Agent_0", ego, states(("Agent_1", 2.0, 5.0, math.pi / 2)))["top_down_rgb"]
    assert tuple(rgb[128, 128 - 32]) == COLOURS["mission_agent"]
    assert tuple(rgb[128, 128 + 32]) != COLOURS["mission_agent"]


@pytest.mark.parametrize(
    ("x", "y", "heading"), [(0.0, -60.0, math.pi / 2), (-3.0, 2.0, 0.3), (40.0, 3.0, math.pi)]
)
def test_drivable_area_matches_the_lane_polygons(junction_road, x, y, heading) -> None:
    bev = BevRenderer(junction_road, interface(img_pixels=128, img_meters=80.0), {})
    ego = EgoPose(x, y, heading, 4.5, 1.8)
    grid = bev.render("Agent_0", ego, VehicleStates.empty())["drivable_area_grid_map"]
    points = pixel_world_points(ego, 128, bev.res).reshape(-1, 2)
    inside = shapely.contains_xy(junction_road.drivable_area, points[:, 0], points[:, 1])
    drawn = grid.reshape(-1) == OCCUPIED
    assert 0.05 < inside.mean() < 0.95  # the crop holds both road and off-road
    wrong = np.flatnonzero(drawn != inside)
    # Rasterising may only disagree with the polygons on their edge: within a pixel of it.
    edge = shapely.distance(junction_road.drivable_area.boundary, shapely.points(points[wrong]))
    assert (edge <= 1.5 / bev.res).all()
    assert len(wrong) / len(drawn) < 0.02


def test_route_is_coloured_on_the_route_only(junction_road) -> None:
    scenario = load_scenario(PUBLIC_T_JUNCTION)
    route = scenario.missions[0].route
    bev = BevRenderer(junction_road, interface(), {"Agent_0": route})
    start = scenario.missions[0].start
    ego = EgoPose(start[0], start[1], start[2], 4.5, 1.8)
    rgb = bev.render("Agent_0", ego, VehicleStates.empty())["top_down_rgb"]
    route_px = np.all(rgb == COLOURS["route"], -1)
    road_px = np.all(rgb == COLOURS["road"], -1)
    assert route_px.sum() > 500 and road_px.sum() > 500
    # Under the ego's start (on its route) the road is the route's colour, a pixel beside the car.
    assert route_px[128, 128 + 5] or route_px[128, 128 - 5]


def rasters_of_a_run(folder: Path, steps: int) -> list[dict[str, np.ndarray]]:
    sim = Simulation(load_scenario(folder), folder, interface())
    try:
        out = [sim.reset()["Agent_0"]]
        for _ in range(steps):
            out.append(sim.step({"Agent_0": [6.0, 0.0]})["Agent_0"])
    finally:
        sim.close()
    return [{k: o[k] for k in ALL_RASTERS} for o in out]


def test_simulated_rasters_show_the_car_ahead_and_are_identical_across_runs(tmp_path) -> None:
    spec = ScenarioSpec(
        missions=(mission(start=(20.0, lane_y(1), 0.0), speed=6.0),),
        vehicles=[vehicle_xml("lead", 42.25, 1, 6.0, vtype="steady")],
    )
    folder = make_scenario(tmp_path / "ahead", spec)
    first, second = rasters_of_a_run(folder, 20), rasters_of_a_run(folder, 20)
    for a, b in zip(first, second, strict=True):
        for name in ALL_RASTERS:
            assert a[name].dtype == np.uint8 and a[name].shape[:2] == (256, 256)
            np.testing.assert_array_equal(a[name], b[name])
    grid = first[0]["occupancy_grid_map"]
    # The lead car's centre is 20 m ahead (departPos is its front bumper): 80 rows up.
    assert grid[128 - 80, 128] == OCCUPIED and grid[128 + 80, 128] == 0
    assert not np.array_equal(first[0]["top_down_rgb"], first[-1]["top_down_rgb"])


def test_only_the_requested_rasters_are_in_the_observation(tmp_path) -> None:
    folder = make_scenario(tmp_path / "plain")
    sim = Simulation(load_scenario(folder), folder, AgentInterface(top_down_rgb=True))
    try:
        obs = sim.reset()["Agent_0"]
    finally:
        sim.close()
    assert obs["top_down_rgb"].shape == (256, 256, 3)
    assert "occupancy_grid_map" not in obs and "drivable_area_grid_map" not in obs
