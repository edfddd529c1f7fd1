"""SumoTraffic: whether our own vehicles are still in SUMO's network; which episodes run SUMO."""

import math

import numpy as np
import pytest

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.interface import ActionSpace, AgentInterface
from sim.road import LanePosition, RoadNetwork
from sim.road.lane import Lane
from sim.road.waypoints import preferred_successor
from sim.simulation import Simulation
from sim.traffic import ALONG_ROUTE, SEARCH_NEAR, SumoTraffic, sumo_mapping, sumo_running
from tests.sim.builders import ScenarioSpec, lane_y, make_scenario

ROAD_END = 400.0  # [m] x of the end of the builders' default straight road


def test_a_watched_vehicle_is_in_the_network_until_sumo_drops_it(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    sc = load_scenario(folder)
    traffic = SumoTraffic(folder / sc.map, folder / sc.traffic.routes, sc.seed, sc.step_length)
    try:
        traffic.add_vehicle("ego", ["E"], 4.5, 1.8)
        traffic.move("ego", 30.0, lane_y(1), 0.0, 5.0)
        traffic.watch_around("ego", 50.0)
        assert traffic.is_in_network("ego")  # waiting to enter at the next step
        traffic.step()
        assert "ego" in traffic.libsumo.vehicle.getContextSubscriptionResults("ego")
        assert traffic.is_in_network("ego")  # driving: answered from its own context report
        traffic.move("ego", ROAD_END - 3.0, lane_y(1), 0.0, 20.0)  # left alone, SUMO drives
        for _ in range(10):  # it past the end of its route and retires it
            traffic.step()
        assert "ego" not in traffic.libsumo.vehicle.getIDList()
        assert not traffic.is_in_network("ego")
    finally:
        traffic.close()


@pytest.mark.parametrize(
    ("scenario_id", "runs_sumo"),
    [
        ("p030_replay_cruise", False),  # every other vehicle replayed outside SUMO
        ("p029_replay_i80_bubble", True),  # replayed vehicles near the egos go into SUMO
        ("p000_left_turn_t_low", True),  # SUMO's traffic
    ],
)
def test_sumo_runs_only_where_a_sumo_vehicle_can_meet_a_mission_vehicle(scenario_id, runs_sumo):
    # A replay without a bubble has no SUMO vehicle to react to the egos or to be seen by them:
    # its episode starts no SUMO (its record is the same, as the regression digests hold).
    folder = SHIPPED_PUBLIC_DIR / scenario_id
    interface = AgentInterface(action_space=ActionSpace.LaneWithContinuousSpeed)
    sim = Simulation(load_scenario(folder), folder, interface)
    try:
        obs = sim.reset()
        for _ in range(3):
            assert sumo_running() is runs_sumo
            obs = sim.step({agent_id: [10.0, 0] for agent_id in obs})
        assert sim.live  # the agents drove on
    finally:
        sim.close()
    assert not sumo_running()


def _lanes_along_route(road: RoadNetwork, start: Lane, route: tuple[str, ...]) -> list[Lane]:
    """The lanes from ``start`` through the junctions to the end of the route's last edge."""
    lanes = [start]
    while lanes[-1].edge_id != route[-1]:
        lanes.append(preferred_successor(road, lanes[-1], route))
    return lanes


def _drive(folder, road: RoadNetwork, lanes: list[Lane], route: list[str], tell_lane: bool):
    """SUMO's lane, lane position and position of an ego moved along the centres of ``lanes``
    every metre, told our map's lane under it (or not)."""
    sc = load_scenario(folder)
    traffic = SumoTraffic(folder / sc.map, folder / sc.traffic.routes, sc.seed, sc.step_length)
    seen = []
    try:
        traffic.add_vehicle("ego", route, 4.5, 1.8)
        for lane in lanes:
            for s in np.arange(0.0, lane.length, 1.0):
                (x, y), (x2, y2) = lane.point_at(s), lane.point_at(s + 0.5)
                heading = math.atan2(y2 - y, x2 - x)
                ours = road.nearest_lane(x, y, heading) if tell_lane else None
                traffic.move("ego", x, y, heading, 10.0, ours)
                traffic.step()
                vehicle = traffic.libsumo.vehicle
                lane_id, s_on_lane = vehicle.getLaneID("ego"), vehicle.getLanePosition("ego")
                seen.append((lane_id, s_on_lane, vehicle.getLateralLanePosition("ego")))
    finally:
        traffic.close()
    return seen


@pytest.mark.parametrize(
    "scenario_id",
    ["p000_left_turn_t_low", "p007_turn_c_right_turn_c_mid", "p017_cruise_3lane_curve_high"],
)
def test_an_ego_on_its_route_is_mapped_where_the_search_near_maps_it(scenario_id):
    # Told our map's lane, SUMO maps an ego on its route along the route's lanes where that
    # gives the same lane, and searches near it as before at junctions, lane ends and the end of
    # the road: on every metre of its route SUMO puts it where the search alone would.
    folder = SHIPPED_PUBLIC_DIR / scenario_id
    sc = load_scenario(folder)
    road = RoadNetwork.load(folder / sc.map)
    mission = sc.missions[0]
    x, y, heading = mission.start
    lanes = _lanes_along_route(road, road.nearest_lane(x, y, heading).lane, mission.route)
    route = list(mission.route)
    told = _drive(folder, road, lanes, route, tell_lane=True)
    assert told == _drive(folder, road, lanes, route, tell_lane=False)
    assert {lane.id for lane in lanes if not lane.is_internal} <= {lane for lane, *_ in told}


def _position(road: RoadNetwork, lane_id: str, s: float) -> LanePosition:
    lane = road.lanes[lane_id]
    x, y = lane.point_at(s)
    return road.nearest_lane(x, y, lane.heading_at(s))


def test_sumo_maps_along_the_route_only_with_the_front_bumper_well_inside_a_route_lane():
    folder = SHIPPED_PUBLIC_DIR / "p000_left_turn_t_low"
    road = RoadNetwork.load(folder / load_scenario(folder).map)
    route = ("s_in", "w_out")
    middle = _position(road, "s_in_0", 50.0)
    along = middle.heading
    assert sumo_mapping(middle, along, 2.25, route) == ALONG_ROUTE
    assert sumo_mapping(None, along, 2.25, route) == SEARCH_NEAR  # our map was not asked
    assert sumo_mapping(middle, along, 2.25, ("e_in",)) == SEARCH_NEAR  # off its route
    # the front bumper nears the junction, or is in it
    end = road.lanes["s_in_0"].length
    assert sumo_mapping(_position(road, "s_in_0", end - 3.0), along, 2.25, route) == SEARCH_NEAR
    junction = _position(road, ":J_4_0", 5.0)
    assert sumo_mapping(junction, junction.heading, 2.25, route) == SEARCH_NEAR
    # turned across the lane: the front bumper nears the next lane (or a ramp's)
    assert sumo_mapping(middle, along + 0.2, 2.25, route) == ALONG_ROUTE
    assert sumo_mapping(middle, along + 0.5, 2.25, route) == SEARCH_NEAR


def test_an_ego_off_its_route_is_mapped_by_the_search_near_it():
    # An ego on a lane of no edge of its route: SUMO searches every lane near it and puts it on
    # the lane it is on (along its route it would be put on the route's nearest lane).
    folder = SHIPPED_PUBLIC_DIR / "p000_left_turn_t_low"
    sc = load_scenario(folder)
    road = RoadNetwork.load(folder / sc.map)
    mission = sc.missions[0]
    off_route = next(
        lane
        for lane in road.lanes.values()
        if not lane.is_internal and not lane.is_shoulder and lane.edge_id not in mission.route
    )
    seen = _drive(folder, road, [off_route], list(mission.route), tell_lane=True)
    assert {lane for lane, *_ in seen[:-3]} == {off_route.id}
