"""Junction outlines that are not valid polygons (real CommonRoad intersections give them): the
road network keeps them as plain valid polygons covering the same area, and every picture of the
road (SVG, rasters) draws them."""

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from sim.bev import BevRenderer, EgoPose
from sim.render import SvgCanvas, draw_road, road_geometry
from sim.road import RoadNetwork
from sim.road.network import polygon_parts
from sim.vehicle.states import VehicleStates
from tests.sim.builders import INVALID_JUNCTION_SHAPES, straight_road, with_junction_shape
from tests.sim.test_bev import interface, pixel_world_points


# Built once per shape for the module: the tests only read the road.
@pytest.fixture(scope="module", params=sorted(INVALID_JUNCTION_SHAPES))
def broken(request, tmp_path_factory) -> tuple[RoadNetwork, list]:
    shape = INVALID_JUNCTION_SHAPES[request.param]
    net = with_junction_shape(straight_road(tmp_path_factory.mktemp(request.param)), "e", shape)
    return RoadNetwork.load(net), shape


def test_shapes_are_invalid_and_repair_to_several_kinds():
    kinds = {shapely.make_valid(Polygon(s)).geom_type for s in INVALID_JUNCTION_SHAPES.values()}
    assert not any(Polygon(s).is_valid for s in INVALID_JUNCTION_SHAPES.values())
    assert kinds == {"MultiPolygon", "GeometryCollection"}


def test_junction_areas_are_valid_polygons_keeping_all_the_area(broken):
    road, shape = broken
    assert road.junction_polygons
    assert all(isinstance(p, Polygon) and p.is_valid for p in road.junction_polygons)
    outline = shapely.make_valid(Polygon(np.add(shape, (400.0, 0.0))))
    kept = shapely.unary_union(road.junction_polygons)
    assert kept.area == pytest.approx(outline.area)  # buffer(0) drops a bow tie's lobe
    assert road.in_junction(400.0 + 6.0, 2.0) == outline.contains(shapely.Point(406.0, 2.0))


def test_every_picture_of_the_road_draws_it(broken):
    road, _ = broken
    geometry = road_geometry(road)
    assert all(p.ndim == 2 and p.shape[1] == 2 for p in geometry.junctions)
    canvas = SvgCanvas.around(road)
    draw_road(canvas, road)
    assert canvas.to_svg().count("<polygon") >= len(road.junction_polygons) + len(road.lanes)
    bev = BevRenderer(road, interface(img_pixels=128, img_meters=64.0), {})
    ego = EgoPose(400.0, 0.0, 0.0, 4.5, 1.8)
    grid = bev.render("Agent_0", ego, VehicleStates.empty())["drivable_area_grid_map"]
    points = pixel_world_points(ego, 128, bev.res).reshape(-1, 2)
    inside = shapely.contains_xy(road.drivable_area, points[:, 0], points[:, 1]).reshape(128, 128)
    assert inside.any() and ((grid > 0) == inside).mean() > 0.98  # edge pixels may differ


def test_polygon_parts_of_every_kind():
    square = Polygon([(0, 0), (1, 0), (1, 1), (0, 1)])
    far = Polygon([(5, 5), (6, 5), (6, 6), (5, 6)])
    assert polygon_parts(square) == [square]
    assert polygon_parts(shapely.MultiPolygon([square, far])) == [square, far]
    mixed = shapely.GeometryCollection([square, shapely.LineString([(0, 0), (3, 3)]), far])
    assert polygon_parts(mixed) == [square, far]
    assert polygon_parts(shapely.LineString([(0, 0), (1, 1)])) == []
    assert polygon_parts(Polygon()) == []
