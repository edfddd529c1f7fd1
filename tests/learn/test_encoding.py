"""Encoding observations into the Gymnasium space, as a submission would in its sandbox."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

import learn.encoding
from learn.spaces import encode_observation, observation_space
from sim.interface import AgentInterface
from submissions.sample import sample_observation


def test_the_sample_observation_encodes_into_the_space() -> None:
    interface = AgentInterface(
        top_down_rgb=True, occupancy_grid_map=True, img_pixels=64, max_waypoint_paths=3
    )
    obs = sample_observation(neighbours=20, rasters=True, img_pixels=64)["Agent_0"]
    encoded = encode_observation(obs, interface, max_neighbours=8)
    assert observation_space(interface, max_neighbours=8).contains(encoded)
    nbr = encoded["neighborhood_vehicle_states"]
    assert nbr["mask"].tolist() == [1] * 8  # 20 neighbours, the first 8 kept
    np.testing.assert_allclose(nbr["position"][:, 0], [110.0 + 5 * n for n in range(8)])
    paths = encoded["waypoint_paths"]
    assert paths["mask"].shape == (3, 50) and paths["mask"].all()
    np.testing.assert_allclose(paths["pos"][2, 10], [110.0, 6.4])  # lane 2, 10 m ahead
    assert encoded["ego_vehicle_state"]["goal_position"].tolist() == [400.0, 0.0]
    assert encoded["top_down_rgb"] is obs["top_down_rgb"]
    assert "drivable_area_grid_map" not in encoded


def test_short_lists_are_padded_and_masked() -> None:
    obs = sample_observation(neighbours=2, waypoints=7)["Agent_0"]
    encoded = learn.encoding.encode(obs, max_paths=4, waypoints=10, max_neighbours=5)
    assert encoded["neighborhood_vehicle_states"]["mask"].tolist() == [1, 1, 0, 0, 0]
    assert encoded["waypoint_paths"]["mask"].sum(1).tolist() == [7, 7, 7, 7]
    assert not encoded["waypoint_paths"]["pos"][:, 7:].any()


def test_the_encoding_module_imports_only_numpy() -> None:
    """A submission copies it into its folder: the sandbox has numpy, not this project."""
    tree = ast.parse(Path(learn.encoding.__file__).read_text())
    imported = {
        alias.name.split(".")[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    } | {node.module.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported == {"numpy", "__future__"}


def test_packing_round_trips_every_leaf() -> None:
    from learn.packing import Layout

    interface = AgentInterface(drivable_area_grid_map=True, img_pixels=32, waypoints_per_path=20)
    space = observation_space(interface, max_neighbours=4)
    encoded = encode_observation(
        sample_observation(rasters=True, img_pixels=32)["Agent_0"], interface, 4
    )
    layout = Layout(space)
    back = layout.unpack(layout.pack(encoded))
    assert space.contains(back)
    for path, *_ in layout.leaves:
        a, b = encoded, back
        for key in path:
            a, b = a[key], b[key]
        np.testing.assert_array_equal(a, b)
        assert a.dtype == b.dtype and a.shape == b.shape
    back["ego_vehicle_state"]["speed"][...] = 1.0  # writable, like the unpacked arrays in use
