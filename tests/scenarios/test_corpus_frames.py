"""Corpus scenes in any coordinate frame, named by their file, their road users by type, and
nothing unsolvable kept: scenes made by the tests from the shipped NGSIM scenes (a georeferenced
copy at UTM coordinates, a rotated and delayed copy, two files with one ``benchmarkID``, a tram
and a motorcycle, a slowed copy no mission of which fits in an episode)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from arena.config import get_settings
from arena.scenario import Family, load_scenario
from arena_command import app
from scenarios.dataset.build import MANIFEST
from scenarios.generators import Spec
from scenarios.picture import draw_scenario
from scenarios.recorded.naturalistic import (
    NaturalisticImportError,
    load_scene,
    scene_net,
    screen_egos,
    write_naturalistic,
)
from scenarios.recorded.naturalistic_pool import TRACKS_FILE, NaturalisticPool
from scenarios.verify import verify_scenario
from tests.cli_runner import CliRunner
from tests.scenarios import corpus_builders as cb
from tests.scenarios.test_dataset import _dataset, _suite_from

runner = CliRunner()
LANKER = "USA_Lanker-1_1_T-1.xml"
UTM = (686000.0, 5335000.0)
CRUISE = Spec(Family.replay, "cruise", None, 1, False)


def _scene_folder(tmp_path: Path, name: str, scenes_dir: Path) -> Path:
    folder = tmp_path / name
    folder.mkdir()
    shutil.copy(scenes_dir / "LICENSE.txt", folder / "LICENSE.txt")
    return folder


def test_a_georeferenced_scene_is_its_original_in_a_local_frame(tmp_path, scenes_dir):
    geo = cb.transformed(scenes_dir / LANKER, tmp_path / "DEU_Geo-1_1_T-1.xml", shift=UTM)
    original, moved = load_scene(scenes_dir / LANKER), load_scene(geo)
    assert original.origin == (0.0, 0.0) and moved.origin == UTM
    for a, b in zip(original.lanelets, moved.lanelets, strict=True):
        np.testing.assert_allclose(b.left, a.left, atol=1e-4)
    for a, b in zip(original.trajectories, moved.trajectories, strict=True):
        np.testing.assert_allclose(np.stack([b.x, b.y]), np.stack([a.x, a.y]), atol=1e-4)


@pytest.mark.slow
def test_a_georeferenced_scene_is_driven_drawn_and_kept_in_a_dataset(tmp_path, scenes_dir):
    """The issue's georeferenced file: the expert was refused at step 1 (a TargetPose beyond
    1e6) and the dataset held none of its vehicles."""
    folder = _scene_folder(tmp_path, "geo", scenes_dir)
    geo = cb.transformed(scenes_dir / LANKER, folder / "DEU_Geo-1_1_T-1.xml", shift=UTM)
    scene = load_scene(geo)
    net = scene_net(scene, tmp_path / "cache")
    egos, _ = screen_egos(scene, net)
    original = load_scene(scenes_dir / LANKER)
    assert [e.vehicle_id for e in egos] == [
        e.vehicle_id for e in screen_egos(original, scene_net(original, tmp_path / "cache"))[0]
    ]
    write_naturalistic(tmp_path / "one", "one", scene, egos[0], net, seed=1)
    assert verify_scenario(tmp_path / "one", tmp_path).solved
    start = load_scenario(tmp_path / "one").missions[0].start
    assert max(abs(start[0]), abs(start[1])) < 1000.0  # the scenario's frame is the local one
    assert "<polygon" in draw_scenario(tmp_path / "one", step=10)
    attribution = (tmp_path / "one" / "ATTRIBUTION.md").read_text()
    assert "less (686000, 5335000) m" in attribution and "public domain" in attribution

    result = _dataset(tmp_path / "dataset", folder, tmp_path=tmp_path)
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "dataset" / MANIFEST).read_text())
    assert len(manifest["episodes"]) == len(egos) and not manifest["unsolved"]
    (listed,) = manifest["scenes"]
    assert listed["file"] == geo.name and listed["origin"] == list(UTM)


@pytest.mark.slow
def test_two_files_with_one_id_are_two_scene_files_of_the_manifest(tmp_path, scenes_dir):
    folder = _scene_folder(tmp_path, "scenes", scenes_dir)
    shutil.copy(scenes_dir / LANKER, folder / LANKER)
    # Another recording under the same benchmarkID, in another file.
    cb.transformed(
        scenes_dir / cb.HIGHWAY_2018, folder / "other.xml", benchmark_id=LANKER.removesuffix(".xml")
    )
    pool = NaturalisticPool.load(folder, "hidden", 3, tmp_path / "cache")
    cut_from = set()
    for i in range(12):
        written = pool.write(tmp_path / "suite", "hidden", i, CRUISE, 1)
        assert written is not None
        text = (tmp_path / "suite" / written[0].id / "ATTRIBUTION.md").read_text()
        cut_from.add(text.split("(file `")[1].split("`")[0])
    listed = pool.scene_list()
    assert cut_from == {"other.xml", LANKER}
    assert {s["file"] for s in listed} == cut_from
    assert len({s["sha256"] for s in listed}) == 2
    assert {s["scene"] for s in listed} == {LANKER.removesuffix(".xml")}
    assert set(pool.track_list()) == cut_from


@pytest.mark.slow
def test_a_rotated_delayed_copy_of_a_suite_scene_is_left_out_of_the_dataset(tmp_path, scenes_dir):
    """The copy is the suite's scene turned by 90 degrees about a far point and 2.5 s later:
    no position of it is one of the suite's, but every vehicle's motion is."""
    hidden_scenes = _scene_folder(tmp_path, "hidden-scenes", scenes_dir)
    shutil.copy(scenes_dir / cb.HIGHWAY_2018, hidden_scenes / cb.HIGHWAY_2018)
    suite = _suite_from(hidden_scenes, tmp_path / "suite", tmp_path / "cache", rows=2)
    scenes = _scene_folder(tmp_path, "scenes", scenes_dir)
    cb.transformed(
        scenes_dir / cb.HIGHWAY_2018,
        scenes / "rotated.xml",
        rotate=math.pi / 2,
        shift=(5000.0, -3000.0),
        time_shift=25,
    )
    shutil.copy(scenes_dir / "USA_Peach-4_8_T-1.xml", scenes / "USA_Peach-4_8_T-1.xml")
    result = _dataset(
        tmp_path / "dataset", scenes, "--exclude-suite", str(suite), tmp_path=tmp_path
    )
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "dataset" / MANIFEST).read_text())
    left = {e["file"]: e["reason"] for e in manifest["excluded_scenes"]}
    assert set(left) == {"rotated.xml"} and "which the suite used" in left["rotated.xml"]
    assert {e["file"] for e in manifest["episodes"]} == {"USA_Peach-4_8_T-1.xml"}
    # What the suite holds of the copy's scene is every vehicle, whatever its frame.
    tracks = json.loads((suite / TRACKS_FILE).read_text())
    assert set(tracks) == {cb.HIGHWAY_2018}


def test_road_user_types_decide_what_a_vehicle_can_be(tmp_path, scenes_dir):
    tram, motorcycle, bicycle = cb.vehicle_ids(scenes_dir / cb.HIGHWAY)[:3]
    path = cb.with_road_user(scenes_dir / cb.HIGHWAY, tmp_path / "a.xml", tram, "train", 15.0)
    cb.with_road_user(path, path, motorcycle, "motorcycle", 2.2)
    cb.with_road_user(path, path, bicycle, "bicycle", 1.8)
    scene = load_scene(path)
    ids = {t.vehicle_id for t in scene.trajectories}
    assert f"cr{tram}" not in ids and f"cr{bicycle}" not in ids  # left out of the replay
    assert scene.left_out == {"bicycle": 1, "train": 1}
    assert scene.types[f"cr{motorcycle}"] == "motorcycle"
    egos, rejected = screen_egos(scene, scene_net(scene, tmp_path / "cache"))
    assert f"cr{motorcycle}" not in {e.vehicle_id for e in egos}  # traffic, never a mission
    assert rejected["traffic_only"] == 1 and rejected["not_replayed"] == 2


@pytest.mark.parametrize("kind", ["set-valued", "point-mass"])
def test_a_file_of_other_state_models_is_skipped_naming_what_it_holds(tmp_path, scenes_dir, kind):
    path = cb.with_states(scenes_dir / cb.HIGHWAY_2018, tmp_path / "a.xml", kind)
    with pytest.raises(NaturalisticImportError) as error:
        load_scene(path)
    assert f"12 with {kind} states" in str(error.value) and "malformed" not in str(error.value)


def test_obstacles_without_an_exact_trajectory_beside_recorded_ones_are_counted(
    tmp_path, scenes_dir
):
    """A file mixing recorded vehicles and a predicted one: the prediction is not replayed, and
    the build says so."""
    path = cb.with_states(scenes_dir / cb.HIGHWAY_2018, tmp_path / "a.xml", "set-valued", 1)
    scene = load_scene(path)
    assert scene.untracked == {"set-valued states": 1} and len(scene.trajectories) == 11
    _, rejected = screen_egos(scene, scene_net(scene, tmp_path / "cache"))
    assert rejected["no_trajectory"] == 1


@pytest.mark.slow
def test_a_mission_the_expert_cannot_finish_never_enters_a_suite_or_dataset(tmp_path, scenes_dir):
    """Every vehicle of the slowed copy drives its path 50 times slower: longer than an
    episode's 800 steps, though every screening check passes."""
    folder = _scene_folder(tmp_path, "slow", scenes_dir)
    cb.transformed(scenes_dir / cb.HIGHWAY_2018, folder / "slow.xml", slower=50)
    pool = NaturalisticPool.load(folder, "hidden", 3, tmp_path / "cache")
    candidates = pool.corpus.candidates()
    assert candidates > 0
    assert pool.write(tmp_path / "suite", "hidden", 0, CRUISE, 1) is None
    assert not any((tmp_path / "suite").iterdir())
    assert pool.unsolved and all("max_episode_steps" in u["reason"] for u in pool.unsolved)
    assert all(u["file"] == "slow.xml" for u in pool.unsolved)

    result = _dataset(tmp_path / "dataset", folder, tmp_path=tmp_path)
    assert result.exit_code == 2, result.output
    assert "the log replay expert finished none of the" in " ".join(
        result.output.replace("│", "").split()
    )
    assert not (tmp_path / "dataset" / MANIFEST).exists()


def test_the_dataset_command_refuses_an_empty_result(tmp_path, scenes_dir):
    folder = _scene_folder(tmp_path, "empty", scenes_dir)
    cb.with_states(scenes_dir / cb.HIGHWAY_2018, folder / "a.xml", "point-mass")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ARENA_DATA_DIR", str(tmp_path / "data"))
        get_settings.cache_clear()
        result = runner.invoke(
            app,
            [
                "dataset",
                "build",
                "--out",
                str(tmp_path / "ds"),
                "--scenes",
                str(folder),
                "--no-public",
            ],
            env={"COLUMNS": "400"},
        )
    get_settings.cache_clear()
    assert result.exit_code == 2
    assert "point-mass states" in result.output


def test_an_ngsim_csv_vehicle_class_decides_what_it_can_be(tmp_path):
    """``v_Class`` 1 is a motorcycle (traffic only), 3 a truck (a mission too)."""
    header = (
        "Vehicle_ID,Frame_ID,Total_Frames,Local_X,Local_Y,v_Length,v_Width,v_Vel,Lane_ID,v_Class\n"
    )
    rows = [
        f"{vid},{100 + f},40,{(vid - 0.5) * 12},{60 * vid + 4 * f},15,6,40,{vid},{cls}\n"
        for vid, cls in ((1, 1), (2, 3))
        for f in range(40)
    ]
    (tmp_path / "scene.csv").write_text(header + "".join(rows))
    scene = load_scene(tmp_path / "scene.csv")
    assert scene.types == {"1": "motorcycle", "2": "truck"}
    egos, rejected = screen_egos(scene, scene_net(scene, tmp_path / "cache"))
    assert [e.vehicle_id for e in egos] == ["2"] and rejected["traffic_only"] == 1
