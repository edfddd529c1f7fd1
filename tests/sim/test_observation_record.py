"""The arrays observation the simulator writes in place (``Simulation(arrays=True)``) is byte for
byte what the encoder makes of the observation dict, on every step of whole episodes, and the
episode (record, done, events, lane ids) is the same."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.experts import PlannerAgent, planner_interface
from sim.interface import AgentInterface
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from sim.simulation import Simulation

PLANNER = planner_interface()
# The planner drives; the interfaces vary what goes into the records: neighbour slots fewer
# than the neighbours, short and fewer paths (paths that end short of their slots), rasters, and
# the smarts2022 format (whose dict paths hold one waypoint more than the arrays keep).
SMALL = PLANNER.model_copy(
    update={"max_neighbours": 2, "max_waypoint_paths": 2, "waypoints_per_path": 7}
)
RASTERS = PLANNER.model_copy(
    update={
        "observation_format": "smarts2022",
        "top_down_rgb": True,
        "occupancy_grid_map": True,
        "drivable_area_grid_map": True,
        "img_pixels": 32,
    }
)
CASES = {
    "p000_left_turn_t_low": PLANNER,  # a junction: paths along the route's junction lane
    "p020_cruise_3lane_curve_low_3agents": SMALL,  # the other egos among the neighbours
    "p021_cut_in_3lane_mid": RASTERS,  # scripted cut-in
    "p029_replay_i80_bubble": PLANNER,  # replayed traffic inside a reactive bubble
    "p030_replay_cruise": SMALL,  # replayed traffic outside SUMO (lanes from our geometry)
    "p035_replay_right_turn": RASTERS,
}


def run(scenario_id: str, interface: AgentInterface, record: Path, actions=None):
    """Drive the episode (the planner's actions, or ``actions`` step by step again); per step,
    agent id -> (record bytes, done, events, road id, lane id), and the actions taken."""
    folder = SHIPPED_PUBLIC_DIR / scenario_id
    arrays = actions is not None
    sim = Simulation(load_scenario(folder), folder, interface, arrays=arrays)
    layout, encoders, planner = ObservationLayout(interface), {}, PlannerAgent()
    seen, taken = [], []
    try:
        obs = sim.reset()
        while True:
            step = {}
            for agent_id, o in obs.items():
                if arrays:
                    step[agent_id] = (bytes(o.record), o.done, o.events, o.road_id, o.lane_id)
                    assert o.arrays["step_count"] == sim.step_count  # views of the record
                else:
                    encoder = encoders.setdefault(agent_id, ObservationEncoder(layout))
                    ego = o["ego_vehicle_state"]
                    events = o["events"]
                    step[agent_id] = (
                        bytes(encoder.encode(o)["dt"].base),
                        o["done"],
                        events,
                        ego["road_id"],
                        ego["lane_id"],
                    )
            seen.append(step)
            if sim.done:
                break
            live = {k: o for k, o in obs.items() if not (o.done if arrays else o["done"])}
            act = actions[len(taken)] if arrays else (planner.act(live) if live else {})
            taken.append(act)
            obs = sim.step(act)
        sim.write_record(record)
    finally:
        sim.close()
    return seen, taken


@pytest.mark.parametrize("scenario_id", sorted(CASES))
def test_records_written_in_place_equal_the_encoded_dicts(scenario_id, tmp_path):
    interface = CASES[scenario_id]
    expected, actions = run(scenario_id, interface, tmp_path / "dicts.npz")
    got, _ = run(scenario_id, interface, tmp_path / "arrays.npz", actions)
    assert len(got) == len(expected) > 10
    for step, (mine, theirs) in enumerate(zip(got, expected, strict=True)):
        assert mine.keys() == theirs.keys(), step
        for agent_id, (record, done, events, road_id, lane_id) in mine.items():
            assert record == theirs[agent_id][0], (step, agent_id)
            assert (done, events.as_observation(), road_id, lane_id) == theirs[agent_id][1:]
    assert (tmp_path / "arrays.npz").read_bytes() == (tmp_path / "dicts.npz").read_bytes()
