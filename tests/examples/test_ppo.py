"""The PPO baseline example: tiny training runs, the ONNX export, and the submission's policy."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest
import yaml

from arena.examples import example_dir
from sim.interface import AgentInterface, ObservationFormat
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from submissions.sample import sample_observation

EXAMPLE = example_dir("ppo")


def example_interface() -> AgentInterface:
    return AgentInterface(**yaml.safe_load((EXAMPLE / "agent.yaml").read_text()))


@pytest.fixture(scope="module")
def example():
    """The example's modules, imported as the sandbox would (its folder first on sys.path)."""
    sys.path.insert(0, str(EXAMPLE))
    try:
        yield {name: importlib.import_module(name) for name in ("train", "policy", "features")}
    finally:
        sys.path.remove(str(EXAMPLE))
        for name in ("train", "policy", "features"):
            sys.modules.pop(name, None)


def test_the_submission_receives_the_training_observation() -> None:
    """``observation_format: arrays``: the sandbox hands the policy what the env trained on."""
    assert example_interface().observation_format is ObservationFormat.arrays


@pytest.mark.slow
def test_onnx_export_gives_the_trained_networks_logits(example, short_road) -> None:
    # Imported here: torch takes seconds to import, and only the slow tests train; onnxruntime (a
    # tenth of a second) only where a test runs an exported network.
    import onnxruntime
    import torch
    from stable_baselines3 import PPO

    train = example["train"]
    env = train.make_env(str(short_road), 0, 0)()
    try:
        model = PPO("MultiInputPolicy", env, n_steps=32, batch_size=32, device="cpu", seed=1)
        model.learn(total_timesteps=32)
    finally:
        env.close()
    path = short_road.parent / "policy.onnx"
    train.export_onnx(model, path)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (3, 3, 64, 64), dtype=np.uint8)
    vector = rng.normal(size=(3, 4)).astype(np.float32)
    (onnx_logits,) = onnxruntime.InferenceSession(str(path)).run(
        None, {"image": image, "vector": vector}
    )
    with torch.no_grad():
        obs = {"image": torch.as_tensor(image), "vector": torch.as_tensor(vector)}
        expected = model.policy.get_distribution(obs).distribution.logits.numpy()
    # SB3 normalises logits (log-softmax); the export gives raw ones: compare after the same.
    np.testing.assert_allclose(
        onnx_logits - np.log(np.exp(onnx_logits).sum(1, keepdims=True)), expected, atol=1e-4
    )


@pytest.mark.slow
def test_a_tiny_training_run_exports_a_policy_the_submission_runs(example, short_road) -> None:
    path = example["train"].train(64, short_road.parent / "tiny", suite=str(short_road), n_steps=32)
    policy = example["policy"].Policy(model=path)
    encoder = ObservationEncoder(ObservationLayout(example_interface()))
    obs = sample_observation(("Agent_0", "Agent_1"), rasters=True, img_pixels=64)
    actions = policy.act({agent_id: encoder.encode(o) for agent_id, o in obs.items()})
    assert set(actions) == {"Agent_0", "Agent_1"}
    for speed, lane_change in actions.values():
        assert 0.0 <= speed <= 14.0 and lane_change in (-1.0, 0.0, 1.0)


def test_the_four_actions_map_onto_lane_with_continuous_speed(example) -> None:
    to_action = example["features"].to_action
    assert to_action(0, 8.0) == [0.0, 0.0]
    assert to_action(1, 8.0) == [10.0, 0.0] and to_action(1, 11.5) == [12.0, 0.0]
    assert to_action(2, 8.0) == [8.0, 1.0] and to_action(3, 1.0) == [3.0, -1.0]


@pytest.mark.slow  # a PPO training run (and torch's import)
def test_training_logs_episode_statistics_and_exports_without_warnings(
    example, short_road, recwarn
) -> None:
    """Monitor-style statistics: every episode's reward, length and end reason in a CSV (and in
    PPO's log); the ONNX export prints no deprecation warning."""
    import csv

    out = short_road.parent / "stats"
    example["train"].train(96, out, suite=str(short_road), n_steps=32)
    rows = []
    for rank in (0, 1):
        lines = (out / f"monitor-{rank}.monitor.csv").read_text().splitlines()
        rows += list(csv.DictReader(lines[1:]))  # the first line is Monitor's JSON header
    assert rows, "no episode finished"
    assert {"r", "l", "t", "done_reason"} <= set(rows[0])
    assert all(int(row["l"]) > 0 for row in rows)
    assert not [w for w in recwarn if "ONNX" in str(w.message) or "removed" in str(w.message)]


@pytest.mark.slow  # stable-baselines3's import (torch)
def test_sb3_check_env_passes_on_the_environment_the_example_trains_on(example, short_road):
    """SB3's checker refuses the raw environment's shape-() scalars (docs/training.md); the
    wrapped one a policy trains on passes it whole."""
    from stable_baselines3.common.env_checker import check_env

    env = example["train"].make_env(str(short_road), 0, 0)()
    try:
        check_env(env, warn=False)
    finally:
        env.close()
