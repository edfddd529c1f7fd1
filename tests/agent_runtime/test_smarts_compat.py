"""The in-sandbox SMARTS 2022 conversion (``agent_runtime/smarts_compat.py``) on sample
observations: attribute access, numpy arrays, SMARTS's heading frame both ways, per-step
``distance_travelled``."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from agent_runtime.smarts_compat import (
    SmartsAdapter,
    from_smarts_heading,
    to_smarts_heading,
)
from submissions.sample import sample_observation


@pytest.mark.parametrize(
    ("ours", "theirs"),
    [(0.0, -math.pi / 2), (math.pi / 2, 0.0), (math.pi, math.pi / 2), (-math.pi / 2, -math.pi)],
)
def test_heading_frames(ours, theirs):
    """East is -pi/2 in SMARTS (0 = north, counter-clockwise), north is 0, west pi/2."""
    assert to_smarts_heading(ours) == pytest.approx(theirs)
    assert math.remainder(from_smarts_heading(theirs) - ours, 2 * math.pi) == pytest.approx(0.0)


def test_observation_has_smarts_fields_numpy_arrays_and_north_zero_headings():
    native = sample_observation()["Agent_0"]
    native["ego_vehicle_state"]["heading"] = math.pi / 2  # driving north
    obs = SmartsAdapter().observations({"Agent_0": native})["Agent_0"]
    ego = obs.ego_vehicle_state
    assert isinstance(ego.position, np.ndarray) and ego.position.shape == (3,)
    assert ego.heading == pytest.approx(0.0)
    assert ego.bounding_box.length == native["ego_vehicle_state"]["bounding_box"][0]
    assert ego.lane_position.t == native["ego_vehicle_state"]["lane_position"][1]
    assert isinstance(ego.linear_velocity, np.ndarray)
    assert ego.mission.goal.position[:2] == pytest.approx(
        native["ego_vehicle_state"]["mission"]["goal"]["position"]
    )
    n0 = native["neighborhood_vehicle_states"][0]
    assert obs.neighborhood_vehicle_states[0].id == n0["id"]
    assert obs.neighborhood_vehicle_states[0].heading == pytest.approx(
        to_smarts_heading(n0["heading"])
    )
    wp0 = native["waypoint_paths"][0][0]
    wp = obs.waypoint_paths[0][0]
    assert isinstance(wp.pos, np.ndarray) and wp.pos == pytest.approx(wp0["pos"][:2])
    assert wp.heading == pytest.approx(to_smarts_heading(wp0["heading"]))
    assert wp.lane_width == wp0["lane_width"] and wp.speed_limit == wp0["speed_limit"]
    assert obs.events.collisions == [] and obs.events.reached_goal is False
    assert obs.steps_completed == 0  # this agent's first observation


def test_distance_travelled_is_per_step_and_restarts_with_the_episode():
    adapter = SmartsAdapter()
    native = sample_observation()["Agent_0"]
    totals = [0.0, 0.8, 1.7, 2.7]
    seen = []
    for total in totals:
        o = copy.deepcopy(native)
        o["distance_travelled"] = total
        seen.append(adapter.observations({"Agent_0": o})["Agent_0"].distance_travelled)
    assert seen == pytest.approx([0.0, 0.8, 0.9, 1.0])
    adapter.reset()
    o = copy.deepcopy(native)
    o["distance_travelled"] = 0.5
    assert adapter.observations({"Agent_0": o})["Agent_0"].distance_travelled == 0.5


def test_target_pose_heading_goes_back_to_our_frame_other_actions_untouched():
    target = SmartsAdapter("TargetPose").actions(
        {"Agent_0": np.array([1.0, 2.0, 0.0, 0.1]), "Agent_1": "junk"}
    )
    assert target["Agent_0"] == pytest.approx([1.0, 2.0, math.pi / 2, 0.1])
    assert target["Agent_1"] == "junk"  # the simulator rules it invalid_action
    lane = SmartsAdapter("LaneWithContinuousSpeed").actions({"Agent_0": [8.0, 0]})
    assert lane == {"Agent_0": [8.0, 0]}


def test_agents_vehicles_carry_smarts_ids_wherever_they_appear():
    """SMARTS named an agent's vehicle ``<agent id>-<8 hex>``: as the ego, as another agent's
    neighbour and as a collidee (whose owner is then that agent); traffic keeps its ids."""
    native = sample_observation(("Agent_0", "Agent_1"), neighbours=2)
    native["Agent_0"]["neighborhood_vehicle_states"][0]["id"] = "Agent_1"
    native["Agent_0"]["events"]["collisions"] = ["Agent_1", "car-1"]
    obs = SmartsAdapter().observations(native)
    ego_ids = {agent: o.ego_vehicle_state.id for agent, o in obs.items()}
    assert all(
        vid.startswith(f"{agent}-") and len(vid) == len(agent) + 9 for agent, vid in ego_ids.items()
    )
    assert ego_ids["Agent_0"] != ego_ids["Agent_1"]
    neighbours = [n.id for n in obs["Agent_0"].neighborhood_vehicle_states]
    assert neighbours == [ego_ids["Agent_1"], "car-1"]
    collisions = obs["Agent_0"].events.collisions
    assert [(c.collidee_id, c.collidee_owner_id) for c in collisions] == [
        (ego_ids["Agent_1"], "Agent_1"),
        ("car-1", ""),
    ]
    # The same agent's vehicle has the same id in every episode: a rerun is identical.
    again = SmartsAdapter().observations(sample_observation(("Agent_0",)))
    assert again["Agent_0"].ego_vehicle_state.id == ego_ids["Agent_0"]
