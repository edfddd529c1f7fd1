"""The arrays observation: its layout, and an encoder that reuses what it saw on earlier steps
giving exactly what a fresh one gives."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sim.interface import AgentInterface
from sim.observation_arrays import RECORD_ALIGN, ObservationEncoder, ObservationLayout
from sim.road import RoadNetwork
from sim.road.waypoints import waypoint_paths
from submissions.sample import sample_observation

PUBLIC = Path(__file__).resolve().parents[2] / "scenarios" / "public"


def leaves(obs: dict, path: tuple = ()) -> dict[tuple, np.ndarray]:
    out = {}
    for key, value in obs.items():
        if isinstance(value, dict):
            out |= leaves(value, (*path, key))
        else:
            out[(*path, key)] = value
    return out


def assert_same(a: dict, b: dict) -> None:
    a, b = leaves(a), leaves(b)
    assert list(a) == list(b)
    for path in a:
        assert a[path].dtype == b[path].dtype and a[path].shape == b[path].shape, path
        np.testing.assert_array_equal(a[path], b[path], err_msg=str(path))


def test_the_sample_observation_encodes_into_its_leaves() -> None:
    interface = AgentInterface(
        top_down_rgb=True,
        occupancy_grid_map=True,
        img_pixels=64,
        max_waypoint_paths=3,
        max_neighbours=8,
    )
    layout = ObservationLayout(interface)
    obs = sample_observation(neighbours=20, rasters=True, img_pixels=64)["Agent_0"]
    encoded = ObservationEncoder(layout).encode(obs)
    for leaf in layout.leaves:
        array = leaves(encoded)[leaf.path]
        assert array.dtype == np.dtype(leaf.dtype) and array.shape == leaf.shape
        assert ((array >= leaf.low) & (array <= leaf.high)).all(), leaf.path
    nbr = encoded["neighborhood_vehicle_states"]
    assert nbr["mask"].tolist() == [1] * 8  # 20 neighbours, the nearest 8 kept
    np.testing.assert_allclose(nbr["position"][:, 0], [110.0 + 5 * n for n in range(8)])
    assert nbr["lane_index"].tolist() == [n % 4 for n in range(8)]
    paths = encoded["waypoint_paths"]
    assert paths["mask"].shape == (3, 50) and paths["mask"].all()
    np.testing.assert_allclose(paths["pos"][2, 10], [110.0, 6.4])  # lane 2, 10 m ahead
    np.testing.assert_allclose(paths["lane_offset"][1, :3], [0.0, 1.0, 2.0])
    ego = encoded["ego_vehicle_state"]
    assert ego["goal_position"].tolist() == [400.0, 0.0]
    assert ego["speed"].shape == (1,) and ego["speed"].item() == 12.0
    assert encoded["step_count"] == 12 and encoded["dt"].dtype == np.float32
    assert not any(encoded["events"].values())
    np.testing.assert_array_equal(encoded["top_down_rgb"], obs["top_down_rgb"])
    assert "drivable_area_grid_map" not in encoded and "done" not in encoded


def test_short_lists_are_padded_and_masked() -> None:
    layout = ObservationLayout(AgentInterface(waypoints_per_path=10, max_neighbours=5))
    obs = sample_observation(neighbours=2, waypoints=7)["Agent_0"]
    obs["events"]["collisions"] = [{"with": "car-1"}]  # a list: its truth is the flag
    encoded = ObservationEncoder(layout).encode(obs)
    assert encoded["neighborhood_vehicle_states"]["mask"].tolist() == [1, 1, 0, 0, 0]
    assert not encoded["neighborhood_vehicle_states"]["position"][2:].any()
    assert encoded["waypoint_paths"]["mask"].sum(1).tolist() == [7, 7, 7, 7]
    assert not encoded["waypoint_paths"]["pos"][:, 7:].any()
    assert encoded["events"]["collisions"] == 1 and encoded["events"]["off_road"] == 0


def test_leaves_are_aligned_and_apart() -> None:
    interface = AgentInterface(
        drivable_area_grid_map=True,
        top_down_rgb=True,
        img_pixels=30,
        waypoints_per_path=7,
        max_neighbours=3,
    )
    layout = ObservationLayout(interface)
    end = 0
    for leaf in layout.leaves:
        assert leaf.offset >= end and leaf.offset % np.dtype(leaf.dtype).itemsize == 0
        end = leaf.offset + leaf.nbytes
    assert layout.size >= end and layout.size % RECORD_ALIGN == 0
    assert json.loads(json.dumps(layout.describe()))["size"] == layout.size


@pytest.mark.slow
def test_a_reused_encoder_gives_what_a_fresh_one_gives_along_a_route() -> None:
    """The encoder remembers waypoint dicts and the last step's paths. A vehicle driving a left
    turn through a junction (paths shift, change lanes, shorten, a new path appears) and
    observations out of order must encode exactly as with an encoder that saw nothing."""
    scenario = PUBLIC / "p002_turn_c_left_turn_c_low"
    road = RoadNetwork.load(scenario / "map.net.xml")
    route = tuple(json.loads((scenario / "scenario.json").read_text())["missions"][0]["route"])
    layout = ObservationLayout(AgentInterface())
    reused = ObservationEncoder(layout)
    lanes = [road.edges[route[0]][0]]
    while len(lanes) < 4 and lanes[-1].successors:
        lanes.append(road.lanes[lanes[-1].successors[0]])
    observations = []
    for lane in lanes:
        for s in np.arange(0.0, lane.length, 1.3):
            x, y = (float(v) for v in lane.position_at(s))
            position = road.nearest_lane(x, y, float(lane.heading_at(s)))
            obs = sample_observation()["Agent_0"]
            obs["waypoint_paths"] = waypoint_paths(road, position, x, y, route, 4, 50)
            observations.append(obs)
    assert len(observations) > 50
    rng = np.random.default_rng(0)
    order = [*range(len(observations)), *rng.permutation(len(observations))]
    for obs in (observations[i] for i in order):
        assert_same(reused.encode(obs), ObservationEncoder(layout).encode(obs))
