"""`arena dataset build`: a Minari dataset from naturalistic and recorded replays whose actions
reproduce the recorded motion; scenes a hidden suite used are left out."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import minari  # the dev extra installs it: no silent skip in CI
import numpy as np
import pytest

from arena.config import get_settings
from arena.scenario import Family
from arena.suite import SHIPPED_PUBLIC_DIR
from arena_command import app
from scenarios.dataset.build import DATASET_ID, MANIFEST, TRANSITIONS
from scenarios.dataset.collect import collect
from scenarios.dataset.features import ACTION_SIZE, OBS_SIZE, to_target_pose
from scenarios.generators import Spec
from scenarios.recorded.builder import EXPERT_FILE
from scenarios.recorded.corpus import read_corpus
from scenarios.recorded.naturalistic import ego_choices, load_scene, scene_net, write_naturalistic
from scenarios.recorded.naturalistic_pool import TRACKS_FILE, NaturalisticPool
from sim.trajectories import read_trajectories
from tests.cli_runner import CliRunner
from tests.scenarios import corpus_builders as cb

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
    assert manifest["excluded_scenes"] == [{"file": HIDDEN, "reason": "the suite used this file"}]
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
        (episode,), unsolved = collect(folder)
        assert unsolved is None
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


def _dataset(out: str | Path, scenes: Path, *args: str, tmp_path: Path, public: bool = False):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ARENA_DATA_DIR", str(tmp_path / "data"))
        mp.setenv("MINARI_DATASETS_PATH", str(tmp_path / "elsewhere"))
        get_settings.cache_clear()
        result = runner.invoke(
            app,
            [
                *("dataset", "build", "--out", str(out), "--scenes", str(scenes)),
                "--public" if public else "--no-public",
                *args,
            ],
            env={"COLUMNS": "400"},
        )
    get_settings.cache_clear()
    return result


def _suite_from(folder: Path, out: Path, cache: Path, rows: int) -> Path:
    """A suite's manifest and tracks file as a build writes them, from ``rows`` cruise missions
    of ``folder``."""
    pool = NaturalisticPool.load(folder, "hidden", 7, cache)
    cruise = Spec(Family.replay, "cruise", None, 1, False)
    for i in range(rows):
        pool.write(out, "hidden", i, cruise, 1)
    (out / "manifest.json").write_text(json.dumps({"naturalistic_scenes": pool.scene_list()}))
    (out / TRACKS_FILE).write_text(json.dumps(pool.track_list()))
    return out


@pytest.mark.slow
def test_a_scene_sharing_one_vehicle_with_the_suite_is_left_out(tmp_path, scenes_dir, monkeypatch):
    """The suite used the first file of a recording cut in two; the second shares vehicles
    under other ids and clock, and never enters the dataset. Output under a relative path."""
    hidden_scenes, scenes = tmp_path / "hidden-scenes", tmp_path / "scenes"
    hidden_scenes.mkdir()
    scenes.mkdir()
    first, second = cb.split_recording(scenes_dir / cb.HIGHWAY, scenes, "USA_Split-1", (30, 70))
    shutil.copy(first, hidden_scenes / first.name)
    shutil.copy(scenes_dir / KEPT, scenes / KEPT)
    suite = _suite_from(hidden_scenes, tmp_path / "suite", tmp_path / "cache", rows=2)
    monkeypatch.chdir(tmp_path)
    result = _dataset("dataset", scenes, "--exclude-suite", str(suite), tmp_path=tmp_path)
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "dataset" / MANIFEST).read_text())
    left = {e["file"]: e["reason"] for e in manifest["excluded_scenes"]}
    assert left[first.name] == "the suite used this file"
    assert "which the suite used" in left[second.name] and "vehicle cr900" in left[second.name]
    assert {e["scene"] for e in manifest["episodes"]} == {KEPT.removesuffix(".xml")}
    assert (tmp_path / "dataset" / DATASET_ID / "data" / "main_data.hdf5").is_file()
    assert f"left out {second.name}: vehicle" in "".join(result.output.split("\n"))


def test_excluding_everything_fails_instead_of_writing_an_empty_dataset(tmp_path, scenes_dir):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(scenes_dir / KEPT, scenes / KEPT)
    suite = _suite_from(scenes, tmp_path / "suite", tmp_path / "cache", rows=1)
    result = _dataset(
        tmp_path / "dataset", scenes, "--exclude-suite", str(suite), tmp_path=tmp_path
    )
    assert result.exit_code == 2
    assert "no episode left: 1 scene files share vehicles with the excluded suite" in " ".join(
        result.output.replace("│", "").split()
    )
    assert not (tmp_path / "dataset" / MANIFEST).exists()


@pytest.mark.slow
def test_unusable_files_are_skipped_and_one_vehicle_is_one_episode(tmp_path, scenes_dir):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    cb.split_recording(scenes_dir / cb.HIGHWAY, scenes, "USA_Split-1", (30, 70))
    cb.without_trajectories(scenes_dir / cb.HIGHWAY, scenes / "USA_Empty-1_1_T-1.xml")
    cb.malformed(scenes / "broken.xml")
    result = _dataset(tmp_path / "dataset", scenes, "--jobs", "2", tmp_path=tmp_path)
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "dataset" / MANIFEST).read_text())
    assert {s["file"] for s in manifest["skipped_scenes"]} == {
        "USA_Empty-1_1_T-1.xml",
        "broken.xml",
    }
    corpus = read_corpus(scenes, tmp_path / "cache")
    identities = [corpus.identity[(e["file"], e["vehicle"])] for e in manifest["episodes"]]
    assert len(identities) == len(set(identities))
    assert len(identities) < corpus.candidates()  # the second file's copies were left out
    assert manifest["rejected_vehicles"].get("short", 0) > 0
