"""The Gymnasium observation space is the layout of the arrays observation, leaf for leaf."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from learn.record_views import RecordViews
from learn.spaces import observation_space
from sim.interface import AgentInterface
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from submissions.sample import sample_observation


def test_encoded_observations_are_members_of_the_space() -> None:
    interface = AgentInterface(
        top_down_rgb=True,
        occupancy_grid_map=True,
        img_pixels=64,
        max_waypoint_paths=3,
        max_neighbours=8,
    )
    space = observation_space(interface)
    encoder = ObservationEncoder(ObservationLayout(interface))
    for neighbours in (0, 3, 20):
        obs = sample_observation(neighbours=neighbours, rasters=True, img_pixels=64)
        assert space.contains(encoder.encode(obs["Agent_0"]))


def test_every_leaf_is_a_box_of_the_layouts_dtype_and_shape() -> None:
    interface = AgentInterface(
        drivable_area_grid_map=True, img_pixels=32, waypoints_per_path=20, max_neighbours=4
    )
    space = observation_space(interface)
    layout = ObservationLayout(interface)
    for leaf in layout.leaves:
        box = space
        for key in leaf.path:
            box = box[key]
        assert isinstance(box, spaces.Box)
        assert box.dtype == np.dtype(leaf.dtype) and box.shape == leaf.shape
        assert np.all(box.low == leaf.low) and np.all(box.high == leaf.high)
    assert len(spaces.flatten_space(space).shape) == 1


def test_records_read_back_as_writable_members_of_the_space() -> None:
    """What the simulator process sends its environment (learn.worker): records, read as views."""
    interface = AgentInterface(top_down_rgb=True, img_pixels=32)
    layout = ObservationLayout(interface)
    record = bytearray(layout.size)
    obs = sample_observation(rasters=True, img_pixels=32)["Agent_0"]
    ObservationEncoder(layout).write(obs, record)
    back = RecordViews(layout).arrays(record)
    assert observation_space(interface).contains(back)
    back["ego_vehicle_state"]["speed"][...] = 1.0  # writable, like any array in use
