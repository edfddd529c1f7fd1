"""Naturalistic scenes (NGSIM via CommonRoad, shipped in scenarios/data/naturalistic): both
CommonRoad formats import, the lanelets become a SUMO map the recorded vehicles drive on, and
every scene gives naturalistic replays the log replay expert solves."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import sumolib

from arena.scenario import DataLabel, load_scenario
from scenarios.recorded.builder import EXPERT_FILE
from scenarios.recorded.commonroad import CommonRoadImportError, read_scene
from scenarios.recorded.lanelet_net import build_lanelet_net, lanelet_edges
from scenarios.recorded.map_match import MAX_ANGLE_RAD, REACH_M, fit_trajectory
from scenarios.recorded.naturalistic import (
    ATTRIBUTION_FILE,
    NaturalisticImportError,
    ego_choices,
    load_scene,
    load_scenes,
    scene_net,
    write_naturalistic,
)
from scenarios.verify import verify_scenario
from sim.road.lane import angle_between
from sim.road.network import RoadNetwork
from sim.trajectories import read_trajectories

# file -> (format, recorded vehicles), as PROVENANCE.md lists them
SHIPPED = {
    "USA_US101-4_1_T-1.xml": ("2020a", 22),
    "USA_US101-3_3_T-1.xml": ("2018b", 12),
    "USA_Lanker-1_1_T-1.xml": ("2018b", 24),
    "USA_Peach-4_8_T-1.xml": ("2020a", 9),
}
# Outside junction areas the simulator's own nearest lane must point the recorded way.
MAX_ANGLE_OUTSIDE_JUNCTIONS = math.radians(20.0)


@pytest.fixture(scope="module")
def nets(scenes_dir, tmp_path_factory) -> dict[str, tuple]:
    cache = tmp_path_factory.mktemp("naturalistic-cache")
    out = {}
    for scene in load_scenes(scenes_dir):
        out[scene.source_file.name] = (scene, scene_net(scene, cache))
    return out


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_both_commonroad_formats_import_trajectories_and_lanelets(scenes_dir, name):
    version, vehicles = SHIPPED[name]
    scene = read_scene(scenes_dir / name)
    assert scene.version == version and scene.dt == pytest.approx(0.1)
    assert len(scene.trajectories) == vehicles
    assert len(scene.lanelets) >= 12
    for lanelet in scene.lanelets:
        assert lanelet.left.shape == lanelet.right.shape
        assert 2.0 < lanelet.width < 6.5  # [m] real lane widths
        assert 5.0 < lanelet.speed_limit < 35.0  # [m/s]
    for tr in scene.trajectories:
        assert np.allclose(np.diff(tr.time), 0.1)
        assert tr.length > 2.0 and tr.width > 1.0


CR2018B = """<?xml version="1.0" encoding="utf-8"?>
<commonRoad commonRoadVersion="2018b" benchmarkID="T-1" timeStepSize="0.1">
  <lanelet id="5">
    <leftBound><point><x>0</x><y>2</y></point><point><x>50</x><y>2</y></point></leftBound>
    <rightBound><point><x>0</x><y>-2</y></point><point><x>50</x><y>-2</y></point></rightBound>
    <speedLimit>13.4112</speedLimit>
  </lanelet>
  <obstacle id="7"><role>static</role><type>parkedVehicle</type>
    <shape><rectangle><length>4</length><width>2</width></rectangle></shape>
    <initialState><position><point><x>1</x><y>1</y></point></position>
      <orientation><exact>0</exact></orientation><time><exact>0</exact></time></initialState>
  </obstacle>
  <obstacle id="8"><role>dynamic</role><type>car</type>
    <shape><rectangle><length>4.2</length><width>1.9</width></rectangle></shape>
    <initialState><position><point><x>1</x><y>0</y></point></position>
      <orientation><exact>0</exact></orientation><time><exact>0</exact></time>
      <velocity><exact>10</exact></velocity></initialState>
    <trajectory><state><position><point><x>2</x><y>0</y></point></position>
      <orientation><exact>0</exact></orientation><time><exact>1</exact></time>
      <velocity><exact>10</exact></velocity></state></trajectory>
  </obstacle>
</commonRoad>
"""


def test_2018b_reads_dynamic_obstacles_and_lanelet_speed_limits(tmp_path):
    (tmp_path / "s.xml").write_text(CR2018B)
    scene = read_scene(tmp_path / "s.xml")
    (lanelet,) = scene.lanelets
    assert lanelet.speed_limit == pytest.approx(13.4112) and lanelet.width == pytest.approx(4.0)
    assert np.allclose(lanelet.centre, [[0, 0], [50, 0]])
    (tr,) = scene.trajectories  # the static obstacle is no trajectory
    assert tr.vehicle_id == "cr8" and np.allclose(tr.x, [1.0, 2.0]) and tr.length == 4.2


def test_malformed_scenes_are_rejected_naming_file_and_problem(tmp_path):
    (tmp_path / "uneven.xml").write_text(CR2018B.replace("<point><x>50</x><y>-2</y></point>", ""))
    with pytest.raises(CommonRoadImportError, match=r"uneven\.xml.*lanelet 5"):
        read_scene(tmp_path / "uneven.xml")
    (tmp_path / "future.xml").write_text(CR2018B.replace("2018b", "2031z"))
    with pytest.raises(CommonRoadImportError, match=r"future\.xml.*'2031z' is not supported"):
        read_scene(tmp_path / "future.xml")
    (tmp_path / "roadless.xml").write_text(CR2018B.split("<lanelet")[0] + "</commonRoad>")
    with pytest.raises(NaturalisticImportError, match=r"roadless\.xml.*no road"):
        load_scene(tmp_path / "roadless.xml")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(NaturalisticImportError, match=r"notes\.txt"):
        load_scene(tmp_path / "notes.txt")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_lanelets_become_sumo_lanes_with_their_width_speed_and_place(nets, name):
    """Each lanelet is a lane of its width and speed limit, in place (coordinates not shifted);
    a short lanelet that netconvert folds into a junction area is covered by that area."""
    scene, net_path = nets[name]
    net = sumolib.net.readNet(str(net_path))
    road = RoadNetwork.load(net_path)
    kept = 0
    for lanelet_id, (edge, index) in lanelet_edges(scene.lanelets).items():
        lanelet = next(ln for ln in scene.lanelets if ln.id == lanelet_id)
        lane = net.getEdge(edge).getLanes()[index]
        assert lane.getWidth() == pytest.approx(lanelet.width, abs=0.01)
        assert lane.getSpeed() == pytest.approx(lanelet.speed_limit, abs=0.01)
        centre = lanelet.centre
        seg = np.linspace(0, 1, 20)[:, None]
        dense = np.concatenate([a + seg * (b - a) for a, b in itertools.pairwise(centre)])
        shape = np.array(lane.getShape())
        on_lane = [
            sumolib.geomhelper.distancePointToPolygon(tuple(p), shape.tolist()) < 0.5 for p in dense
        ]
        kept += on_lane[len(on_lane) // 2]  # the lanelet's middle is on its own lane
        # (the end points themselves are on the border of the neighbouring junction area)
        for p, ok in zip(dense[1:-1], on_lane[1:-1], strict=True):
            assert ok or road.in_junction(*p), (lanelet_id, p)
    assert kept >= 0.6 * len(scene.lanelets)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_every_recorded_vehicle_drives_on_lanes_of_the_map_in_their_direction(nets, name):
    """Tolerance: every recorded pose of every vehicle lies within a lane's half width + 0.5 m and
    within 45 degrees of its direction; outside junction areas the simulator's nearest lane (what
    events and observations use) is within 20 degrees."""
    scene, net_path = nets[name]
    road = RoadNetwork.load(net_path)
    for tr in scene.trajectories:
        fits = fit_trajectory(road, tr)
        assert all(f.lane is not None for f in fits), tr.vehicle_id
        assert max(f.excess_m for f in fits) <= REACH_M
        assert max(f.angle_rad for f in fits) <= MAX_ANGLE_RAD
        for x, y, h in zip(tr.x, tr.y, tr.heading, strict=True):
            assert road.is_on_road(x, y), (tr.vehicle_id, x, y)
            if not road.in_junction(x, y):
                lane = road.nearest_lane(x, y, h)
                assert angle_between(h, lane.heading) <= MAX_ANGLE_OUTSIDE_JUNCTIONS


@pytest.fixture(scope="module")
def naturalistic_scenarios(nets, tmp_path_factory) -> list[Path]:
    out = tmp_path_factory.mktemp("naturalistic")
    folders = []
    for scene, net_path in nets.values():
        for ego in ego_choices(scene, net_path):
            folder = out / f"{scene.name}_{ego.vehicle_id}"
            write_naturalistic(folder, folder.name, scene, ego, net_path, seed=1)
            folders.append(folder)
    return folders


@pytest.mark.slow
def test_every_scene_gives_several_ego_choices(naturalistic_scenarios):
    per_scene: dict[str, int] = {}
    for folder in naturalistic_scenarios:
        scene = folder.name.rsplit("_cr", 1)[0]
        per_scene[scene] = per_scene.get(scene, 0) + 1
    assert set(per_scene) == {name.removesuffix(".xml") for name in SHIPPED}
    assert min(per_scene.values()) >= 3


def test_naturalistic_scenario_replaces_one_recorded_vehicle(nets, naturalistic_scenarios):
    for folder in naturalistic_scenarios:
        scenario = load_scenario(folder)
        assert scenario.label is DataLabel.naturalistic
        assert scenario.traffic.label is DataLabel.naturalistic and not scenario.reactive
        assert scenario.variant.startswith("ngsim_")
        scene = nets[f"{folder.name.rsplit('_cr', 1)[0]}.xml"][0]
        removed = "cr" + folder.name.rsplit("_cr", 1)[1]
        recorded = next(t for t in scene.trajectories if t.vehicle_id == removed)
        (mission,) = scenario.missions
        assert mission.start[:2] == pytest.approx((recorded.x[0], recorded.y[0]), abs=1e-3)
        assert mission.goal.position == pytest.approx((recorded.x[-1], recorded.y[-1]), abs=1e-3)
        assert removed not in read_trajectories(folder / "trajectories.csv")
        assert len(read_trajectories(folder / EXPERT_FILE)["Agent_0"].x) == len(recorded.x)
        attribution = (folder / ATTRIBUTION_FILE).read_text()
        assert "NGSIM" in attribution and "BSD" in attribution and "OpenStreetMap" in attribution


@pytest.mark.slow
def test_log_replay_expert_solves_every_naturalistic_scenario(naturalistic_scenarios, tmp_path):
    unsolved = [
        (folder.name, r.reason)
        for folder in naturalistic_scenarios
        if not (r := verify_scenario(folder, tmp_path)).solved
    ]
    assert not unsolved
    # Driving the recorded path on the built map is neither off route nor the wrong way.
    for folder in naturalistic_scenarios:
        record = np.load(tmp_path / f"{folder.name}.npz")
        assert record["ev_off_route"].sum() == 0 and record["ev_wrong_way"].sum() == 0, folder.name


@pytest.mark.slow
def test_ngsim_csv_scene_gets_straight_lanes_and_solvable_scenarios(tmp_path):
    """An NGSIM CSV scene (no road in the file): one straight 12 ft lane per Lane_ID; vehicles
    40 ft apart in lanes 1-3 at 40 ft/s, one drifting from lane 2 into lane 3."""
    header = "Vehicle_ID,Frame_ID,Total_Frames,Local_X,Local_Y,v_Length,v_Width,v_Vel,Lane_ID\n"
    rows = []
    for vid, lane in ((1, 1), (2, 2), (3, 3), (4, 2)):
        for f in range(40):
            local_x = (lane - 0.5) * 12 + (0.3 * max(0, f - 10) if vid == 4 else 0.0)
            local_x = min(local_x, 2.5 * 12)
            local_y = 60 * vid + 4 * f
            rows.append(f"{vid},{100 + f},40,{local_x},{local_y},15,6,40,{lane}\n")
    (tmp_path / "us101-sample.csv").write_text(header + "".join(rows))
    scene = load_scene(tmp_path / "us101-sample.csv")
    assert len(scene.lanelets) == 3 and len(scene.trajectories) == 4
    net_path = scene_net(scene, tmp_path / "cache")
    net = sumolib.net.readNet(str(net_path))
    (edge,) = net.getEdges()
    assert [round(lane.getWidth(), 3) for lane in edge.getLanes()] == [3.658] * 3
    egos = ego_choices(scene, net_path)
    assert {e.vehicle_id for e in egos} == {"1", "2", "3", "4"}
    assert next(e for e in egos if e.vehicle_id == "4").kind == "lane_change"
    for ego in egos:
        folder = tmp_path / f"ngsim_{ego.vehicle_id}"
        write_naturalistic(folder, folder.name, scene, ego, net_path, seed=1)
        assert verify_scenario(folder, tmp_path).solved


def _straight(lid, y_right, *, left=None, right=None):
    from scenarios.recorded.commonroad import Lanelet

    return Lanelet(
        lid,
        np.array([[0.0, y_right + 3.5], [80.0, y_right + 3.5]]),
        np.array([[0.0, y_right], [80.0, y_right]]),
        (),
        (),
        left,
        right,
        20.0,
    )


@pytest.mark.slow
def test_side_by_side_lanelets_are_one_edge_and_bad_neighbour_loops_are_not(tmp_path):
    pair = [_straight(1, 0.0, left=2), _straight(2, 3.5, right=1)]
    assert lanelet_edges(pair) == {1: ("cr1_2", 0), 2: ("cr1_2", 1)}
    net = sumolib.net.readNet(str(build_lanelet_net("pair", pair, tmp_path)))
    lanes = net.getEdge("cr1_2").getLanes()
    assert [round(np.mean([p[1] for p in ln.getShape()]), 2) for ln in lanes] == [1.75, 5.25]
    # Each names the other as its right neighbour (only 4 is): every lanelet kept, no loop.
    looped = [_straight(3, 0.0, right=4), _straight(4, -3.5, right=3)]
    assert set(lanelet_edges(looped)) == {3, 4}


@pytest.mark.slow
def test_a_track1_agent_drives_the_imported_maps(naturalistic_scenarios, tmp_path):
    """The reference planner (waypoints, observations, events on the imported lanes) runs one
    scenario of every scene without a simulator error and reaches some goals."""
    from scenarios.experts import PlannerAgent, planner_interface
    from sim.isolation import run_episode_isolated

    first = {}
    for folder in naturalistic_scenarios:
        first.setdefault(folder.name.rsplit("_cr", 1)[0], folder)
    reached = 0
    for folder in first.values():
        result = run_episode_isolated(
            folder, PlannerAgent, planner_interface(), record_path=tmp_path / f"{folder.name}.npz"
        )
        assert not result.simulator_error, (folder.name, result.simulator_error)
        reached += result.agents[0].reached_goal
    assert reached >= 1
