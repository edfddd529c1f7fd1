"""SumoTraffic: whether our own vehicles are still in SUMO's network."""

from arena.scenario import load_scenario
from sim.traffic import SumoTraffic
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
