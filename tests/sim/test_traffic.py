"""SumoTraffic: whether our own vehicles are still in SUMO's network; which episodes run SUMO."""

import pytest

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.interface import ActionSpace, AgentInterface
from sim.simulation import Simulation
from sim.traffic import SumoTraffic, sumo_running
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
