"""`arena dataset build`: a Minari dataset from naturalistic and recorded replays whose actions
reproduce the recorded motion; scenes a hidden suite used are left out."""

from __future__ import annotations

import hashlib
import json
import shutil

import minari  # the dev extra installs it: no silent skip in CI
import numpy as np
import pytest
from typer.testing import CliRunner

from arena.cli import app
from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.dataset.build import DATASET_ID, MANIFEST, TRANSITIONS
from scenarios.dataset.collect import collect
from scenarios.dataset.features import ACTION_SIZE, OBS_SIZE, to_target_pose
from scenarios.recorded.builder import EXPERT_FILE
from scenarios.recorded.naturalistic import ego_choices, load_scene, scene_net, write_naturalistic
from sim.trajectories import read_trajectories

runner = CliRunner()
KEPT, HIDDEN = "USA_US101-3_3_T-1.xml", "USA_Peach-4_8_T-1.xml"
RECORDED = "p033_replay_merge_2agents"


@pytest.mark.slow
def test_dataset_loads_with_minari_and_leaves_out_hidden_scenes(tmp_path, scenes_dir, monkeypatch):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    for name in (KEPT, HIDDEN, "LICENSE.txt"):
        shutil.copy(scenes_dir / name, scenes / name)
    public = tmp_path / "public"
    shutil.copytree(SHIPPED_PUBLIC_DIR / RECORDED, public / RECORDED)
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    sha = hashlib.sha256((scenes_dir / HIDDEN).read_bytes()).hexdigest()
    (hidden / "manifest.json").write_text(
        json.dumps({"naturalistic_scenes": [{"file": HIDDEN, "sha256": sha}]})
    )
    out = tmp_path / "dataset"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(out))  # restored after the test
    monkeypatch.setenv("ARENA_PUBLIC_SUITE_DIR", str(public))
    monkeypatch.setenv("ARENA_DATA_DIR", str(tmp_path / "data"))
    from arena.config import get_settings

    get_settings.cache_clear()
    result = runner.invoke(
        app,
        [
            "dataset",
            "build",
            "--out",
            str(out),
            "--scenes",
            str(scenes),
            "--exclude-suite",
            str(hidden),
        ],
    )
    get_settings.cache_clear()
    assert result.exit_code == 0, result.output
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["excluded_scenes"] == [HIDDEN]
    episodes = manifest["episodes"]
    natural = [e for e in episodes if e["source"] == "NGSIM"]
    assert {e["scene"] for e in natural} == {KEPT.removesuffix(".xml")}
    assert len(natural) == len(ego_choices(*_scene_and_net(scenes / KEPT, tmp_path)))
    assert [(e["scene"], e["agent"]) for e in episodes if e["source"] == "recorded"] == [
        (RECORDED, "Agent_0"),
        (RECORDED, "Agent_1"),
    ]

    dataset = minari.load_dataset(DATASET_ID)
    assert dataset.total_episodes == len(episodes)
    assert dataset.total_steps == sum(e["steps"] for e in episodes)
    for row, ep in zip(episodes, dataset.iterate_episodes(), strict=True):
        assert ep.observations.shape == (row["steps"] + 1, OBS_SIZE)
        assert ep.actions.shape == (row["steps"], ACTION_SIZE)
        assert ep.truncations[-1] and not ep.truncations[:-1].any()
        assert not ep.terminations.any()  # the expert never crashes
        assert np.isfinite(ep.rewards).all() and ep.rewards.sum() > 0  # it makes progress
    # The numpy export a sandboxed train.py reads holds the very same transitions.
    flat = np.load(out / TRANSITIONS)
    every = list(dataset.iterate_episodes())
    np.testing.assert_array_equal(flat["actions"], np.concatenate([e.actions for e in every]))
    np.testing.assert_array_equal(
        flat["observations"], np.concatenate([e.observations[:-1] for e in every])
    )
    np.testing.assert_array_equal(
        flat["next_observations"], np.concatenate([e.observations[1:] for e in every])
    )
    assert flat["episode"].max() == len(episodes) - 1


def _scene_and_net(path, tmp_path):
    scene = load_scene(path)
    return scene, scene_net(scene, tmp_path / "cache")


@pytest.mark.slow
def test_actions_reproduce_the_recorded_motion(tmp_path, scenes_dir):
    """Tolerance: the pose each action targets is the next observed pose within 1 cm and
    0.01 rad, and observed poses are the recorded trajectory within 5 cm."""
    scene, net = _scene_and_net(scenes_dir / "USA_Lanker-1_1_T-1.xml", tmp_path)
    for ego in ego_choices(scene, net)[:3]:
        folder = tmp_path / ego.vehicle_id
        write_naturalistic(folder, folder.name, scene, ego, net, seed=0)
        (episode,) = collect(folder)
        recorded = read_trajectories(folder / EXPERT_FILE)["Agent_0"]
        n = len(episode.poses)
        assert (
            np.hypot(
                recorded.x[:n] - episode.poses[:, 0], recorded.y[:n] - episode.poses[:, 1]
            ).max()
            < 0.05
        )
        for t, action in enumerate(episode.actions):
            x, y, h, _ = to_target_pose(tuple(episode.poses[t]), action)
            nx, ny, nh = episode.poses[t + 1]
            assert abs(x - nx) < 0.01 and abs(y - ny) < 0.01
            assert abs((h - nh + np.pi) % (2 * np.pi) - np.pi) < 0.01
