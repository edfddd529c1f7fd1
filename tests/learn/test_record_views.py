"""learn's reader of arrays records gives the layout's own observation dict."""

from __future__ import annotations

import numpy as np
import pytest

from learn.record_views import RecordViews
from sim.interface import AgentInterface
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from submissions.sample import sample_observation


def _leaves(obs: dict, path: tuple[str, ...] = ()):
    for key, value in obs.items():
        if isinstance(value, dict):
            yield from _leaves(value, (*path, key))
        else:
            yield (*path, key), value


@pytest.mark.parametrize(
    "interface",
    [
        AgentInterface(),
        AgentInterface(
            top_down_rgb=True,
            occupancy_grid_map=True,
            drivable_area_grid_map=True,
            img_pixels=16,
            max_waypoint_paths=2,
            waypoints_per_path=7,
            max_neighbours=3,
        ),
    ],
)
def test_the_views_are_the_layouts_arrays_over_the_same_record(interface) -> None:
    layout = ObservationLayout(interface)
    record = bytearray(layout.size)
    obs = sample_observation(neighbours=5, rasters=True, img_pixels=interface.img_pixels)
    ObservationEncoder(layout).write(obs["Agent_0"], record)
    expected, got = layout.arrays(record), RecordViews(layout).arrays(record)
    pairs = list(zip(_leaves(expected), _leaves(got), strict=True))
    assert len(pairs) == len(layout.leaves)
    for (path, want), (got_path, view) in pairs:
        assert got_path == path  # the same nesting, keys in the same order
        assert (view.dtype.str, view.shape) == (want.dtype.str, want.shape)
        assert view.flags.writeable and view.flags.c_contiguous
        assert np.shares_memory(view, want)
        np.testing.assert_array_equal(view, want)
    got["ego_vehicle_state"]["speed"][...] = 42.0  # views: written through to the record
    assert layout.arrays(record)["ego_vehicle_state"]["speed"].item() == 42.0
