"""An agent written as the Driving SMARTS 2022 organisers' example was (``comp1_agent/``: SMARTS
``comp-1``'s ``competition/track1/submission`` layout, imports and wrappers, comp-1's
``FormatObs`` keys, ``smarts.core.colors``, ``FrameStack`` under a concatenating wrapper, and a
stable-baselines3 PPO model loaded with ``PPO.load``) runs unmodified on public scenarios in each
sandbox, with only what ``docs/smarts-compat.md`` prescribes (issue 41).

The model is made here: a small PPO over the observation space the agent's wrappers build, its
action head set to always choose "straight on at 30 km/h", so what the episodes record shows the
model's choice went through every wrapper to the simulator."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from evaluator.scoring import load_record
from tests.agent_runtime.ported import SANDBOXES, run_ported

pytestmark = pytest.mark.slow

AGENT = Path(__file__).parent / "comp1_agent"
STRAIGHT = 1  # the agent's action.py: straight on at 30 km/h
SPEED = 30 / 3.6  # [m/s]
PIXELS = 64  # agent.yaml's img_pixels
FRAMES = 3  # the FrameStack of policy.py
SCENARIOS = ["p016_cruise_2lane_low", "p010_merge_2lane_shoulder_mid_2agents"]


def make_model(folder: Path) -> None:
    """``folder/saved_model.zip``: PPO with the agent's own feature extractor over the space its
    wrappers give (channels-first stacked image, goal distance and heading), always straight."""
    gymnasium = pytest.importorskip("gymnasium")
    sb3 = pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    spec = importlib.util.spec_from_file_location("network", folder / "network.py")
    network = importlib.util.module_from_spec(spec)
    sys.modules["network"] = network  # pickled by reference, as the kit's model was
    spec.loader.exec_module(network)
    box = gymnasium.spaces.Box
    space = gymnasium.spaces.Dict(
        {
            "rgb": box(0, 255, (3 * FRAMES, PIXELS, PIXELS), np.uint8),
            "goal_distance": box(-1e10, 1e10, (FRAMES, 1), np.float32),
            "goal_heading": box(-np.pi, np.pi, (FRAMES, 1), np.float32),
        }
    )

    class Still(gymnasium.Env):
        observation_space = space
        action_space = gymnasium.spaces.Discrete(4)

        def reset(self, *, seed=None, options=None):
            return space.sample(), {}

        def step(self, action):
            return space.sample(), 0.0, True, False, {}

    model = sb3.PPO(
        "MultiInputPolicy",
        Still(),
        n_steps=8,
        batch_size=8,
        device="cpu",
        seed=0,
        policy_kwargs={
            "features_extractor_class": network.CombinedExtractor,
            "features_extractor_kwargs": {"cnn_output_dim": 16},
            "net_arch": [],
        },
    )
    head = model.policy.action_net
    with torch.no_grad():
        head.weight.zero_()
        head.bias.copy_(torch.tensor([0.0, 5.0, 0.0, 0.0]))
    model.save(folder / "saved_model.zip")
    del sys.modules["network"]


@pytest.fixture(scope="module")
def agent(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("comp1") / "agent"
    shutil.copytree(AGENT, folder)
    make_model(folder)
    return folder


@pytest.mark.parametrize("kind", SANDBOXES)
def test_the_organisers_example_style_agent_runs_unmodified(kind, agent, tmp_path):
    out = tmp_path / "out"
    summary, _ = run_ported(agent, SCENARIOS, kind, out)
    # The model's choice, through FilterObs, FrameStack, Concatenate, the discrete action and
    # FormatAction, drove every agent straight on at 30 km/h from its second step.
    for scenario_id in SCENARIOS:
        record = load_record(out / "records" / f"{scenario_id}.npz")
        for track in record.tracks:
            assert np.allclose(track.speed[2:], SPEED, atol=0.2), (scenario_id, track.speed[:8])
    (environment,) = summary.manifest.environments
    assert environment.agent_stack["stable_baselines3"] == "2.9.2"
    assert environment.agent_stack["torch"].startswith("2.13.0")
