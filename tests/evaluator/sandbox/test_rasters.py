"""BEV rasters cross the sandbox protocol and reach the policy as numpy arrays."""

from __future__ import annotations

import numpy as np
import pytest

from evaluator.sandbox import start
from submissions.sample import sample_observation
from tests.evaluator.sandbox.agents import agent
from tests.settings import sandbox_args

# The policy reports what it received: type, dtype, shape and a checksum of each raster.
REPORT = """
out = []
for name in ('top_down_rgb', 'occupancy_grid_map', 'drivable_area_grid_map'):
    image = obs['Agent_0'][name]
    assert isinstance(image, np.ndarray) and image.dtype == np.uint8, type(image)
    weights = np.arange(image.size).reshape(image.shape)
    out += [*image.shape, int(image.astype(np.int64).sum()), int((image * weights % 251).sum())]
return {'Agent_0': out}
"""


def checksums(obs: dict) -> list[int]:
    out = []
    for name in ("top_down_rgb", "occupancy_grid_map", "drivable_area_grid_map"):
        image = obs["Agent_0"][name]
        weights = np.arange(image.size).reshape(image.shape)
        out += [*image.shape, int(image.astype(np.int64).sum()), int((image * weights % 251).sum())]
    return out


def test_sample_rasters_reach_the_policy_as_uint8_arrays(any_kind, settings, labels, tmp) -> None:
    submission = agent(tmp, settings, act=REPORT)
    obs = sample_observation(rasters=True, img_pixels=96, img_meters=48.0)
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        received = handle.act(obs)["Agent_0"]
    assert received == checksums(obs)
    assert received[:3] == [96, 96, 3] and received[3] > 0  # a real picture, not zeros


@pytest.mark.slow
def test_the_ppo_example_drives_from_rasters_in_the_sandbox(any_kind, settings, labels, tmp):
    """The committed PPO baseline (onnxruntime from its requirements.txt) answers a rastered
    observation with LaneWithContinuousSpeed actions."""
    from tests.evaluator.sandbox.test_sandbox import packed_example

    submission = packed_example("ppo", tmp, settings)
    assert submission.deps_dir is not None  # onnxruntime, installed from wheels
    obs = sample_observation(("Agent_0", "Agent_1"), rasters=True, img_pixels=64)
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        actions = handle.act(obs)
    assert set(actions) == {"Agent_0", "Agent_1"}
    for speed, lane_change in actions.values():
        assert 0.0 <= speed <= 14.0 and lane_change in (-1.0, 0.0, 1.0)
