"""`arena scenarios build --suite hidden --naturalistic-dir DIR` over a generated corpus of the
shipped scenes mixed with broken files, one recording split into two overlapping scene files, a
scene of simulated traffic, a scene with a 20 m truck, a georeferenced copy (UTM coordinates), a
rotated and delayed copy, a shifted copy under another file's id, a scene with a tram and a
motorcycle, and files of set-valued and point-mass states: unusable files are skipped with what
they hold, every mission is one its recorded driver finishes (the log replay expert solves every
corpus scenario), no recorded vehicle is the mission of two scenarios however its file was moved,
rows are filled by kind, and provenance comes from the files, by name and content."""

from __future__ import annotations

import hashlib
import json
import math
import re
import shutil
from pathlib import Path

import pytest

from arena.config import get_settings
from arena.scenario import DataLabel, Family, load_scenario
from arena_command import app
from scenarios.generators import Spec
from scenarios.picture import draw_scenario
from scenarios.recorded.corpus import read_corpus
from scenarios.recorded.naturalistic import ATTRIBUTION_FILE, collides, load_scene
from scenarios.recorded.naturalistic_pool import TRACKS_FILE, NaturalisticPool
from scenarios.recorded.tracks import recording_location
from scenarios.suites import REPLAYS
from scenarios.verify import verify_scenario
from scenarios.writer import TRAJECTORIES_FILE
from sim.trajectories import read_trajectories
from tests.cli_runner import CliRunner
from tests.scenarios import corpus_builders as cb
from tests.scenarios.conftest import manifest

runner = CliRunner()
SIMULATED = "OpenStreetMaps, SUMO Traffic Simulator"
GEO = "DEU_Geo-1_1_T-1.xml"  # the shipped Lanker scene at UTM coordinates
UTM = (686000.0, 5335000.0)
BROKEN = {
    "USA_Empty-1_1_T-1.xml": "no recorded vehicle trajectory (22 obstacles without one",
    "setvalued.xml": "(12 obstacles without one: 12 with set-valued states)",
    "pointmass.xml": "(22 obstacles without one: 22 with point-mass states)",
    "broken.xml": "not a readable CommonRoad scenario",
    "old.xml": "CommonRoad format '2017a' is not supported",
}


def _first_vehicle(path: Path) -> str:
    return cb.vehicle_ids(path)[0]


@pytest.fixture(scope="module")
def corpus_dir(tmp_path_factory, scenes_dir) -> Path:
    folder = tmp_path_factory.mktemp("corpus")
    for name in ("USA_Lanker-1_1_T-1.xml", "USA_Peach-4_8_T-1.xml", "LICENSE.txt"):
        shutil.copy(scenes_dir / name, folder / name)
    cb.split_recording(scenes_dir / cb.HIGHWAY, folder, "USA_Split-1", (30, 70))
    truck_car = _first_vehicle(scenes_dir / cb.HIGHWAY_2018)
    cb.with_truck_ahead(scenes_dir / cb.HIGHWAY_2018, folder / "USA_Truck-1_1_T-1.xml", truck_car)
    cb.copy_scene(
        scenes_dir / cb.HIGHWAY_2018, folder / "sim.xml", "DEU_Sim-1_1_T-1", source=SIMULATED
    )
    cb.without_trajectories(scenes_dir / cb.HIGHWAY, folder / "USA_Empty-1_1_T-1.xml")
    cb.malformed(folder / "broken.xml")
    cb.unsupported_version(scenes_dir / cb.HIGHWAY, folder / "old.xml")
    cb.transformed(scenes_dir / "USA_Lanker-1_1_T-1.xml", folder / GEO, shift=UTM)
    cb.transformed(
        scenes_dir / "USA_Peach-4_8_T-1.xml",
        folder / "rotated.xml",
        rotate=math.pi / 2,
        time_shift=25,
        benchmark_id="USA_Rot-1_1_T-1",
    )
    # Another scene under the id of a shipped one: two files, one benchmarkID.
    cb.transformed(
        scenes_dir / cb.HIGHWAY_2018,
        folder / "shifted.xml",
        shift=(300.0, -40.0),
        benchmark_id="USA_Lanker-1_1_T-1",
    )
    tram, motorcycle = cb.vehicle_ids(scenes_dir / cb.HIGHWAY)[:2]
    cb.with_road_user(scenes_dir / cb.HIGHWAY, folder / "USA_Tram-1_1_T-1.xml", tram, "train", 15.0)
    cb.with_road_user(
        folder / "USA_Tram-1_1_T-1.xml",
        folder / "USA_Tram-1_1_T-1.xml",
        motorcycle,
        "motorcycle",
        2.2,
    )
    cb.with_states(scenes_dir / cb.HIGHWAY_2018, folder / "setvalued.xml", "set-valued")
    cb.with_states(scenes_dir / cb.HIGHWAY, folder / "pointmass.xml", "point-mass")
    return folder


@pytest.fixture(scope="module")
def hidden_corpus(tmp_path_factory, cache_dir, corpus_dir) -> Path:
    root = tmp_path_factory.mktemp("hidden-corpus")
    out = root / "suite"
    # The CLI's cache (ARENA_DATA_DIR/cache/scenarios) is the session's, so recordings are shared.
    (root / "data" / "cache").mkdir(parents=True)
    (root / "data" / "cache" / "scenarios").symlink_to(cache_dir)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ARENA_DATA_DIR", str(root / "data"))
        get_settings.cache_clear()
        result = runner.invoke(
            app,
            [
                *("scenarios", "build", "--suite", "hidden", "--dev", "--out", str(out)),
                *("--naturalistic-dir", str(corpus_dir), "--jobs", "2"),
            ],
            env={"COLUMNS": "400"},
        )
    get_settings.cache_clear()
    assert result.exit_code == 0, result.output
    (out / "build-output.txt").write_text(result.output)
    return out


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_unusable_files_are_skipped_and_named_with_their_reason(hidden_corpus):
    skipped = {s["file"]: s["reason"] for s in manifest(hidden_corpus)["naturalistic_skipped"]}
    assert set(skipped) == set(BROKEN)
    for file, reason in BROKEN.items():
        assert reason in skipped[file]
    output = (hidden_corpus / "build-output.txt").read_text()
    for file, reason in BROKEN.items():
        assert f"skipped {file}: " in output and reason in output


def test_a_folder_without_a_usable_mission_fails_naming_every_file(tmp_path, scenes_dir):
    folder = tmp_path / "scenes"
    folder.mkdir()
    cb.without_trajectories(scenes_dir / cb.HIGHWAY, folder / "USA_Empty-1_1_T-1.xml")
    cb.malformed(folder / "broken.xml")
    out = tmp_path / "hidden"
    result = runner.invoke(
        app,
        ["scenarios", "build", "--dev", "--out", str(out), "--naturalistic-dir", str(folder)],
        env={"COLUMNS": "400"},
    )
    assert result.exit_code == 2
    text = "".join(result.output.replace("│", "").split())
    assert "nousablemissionin0usableof2scenefiles" in text
    assert "USA_Empty-1_1_T-1.xml:thescenehasnorecordedvehicletrajectory" in text
    assert "broken.xml:notareadableCommonRoadscenario" in text
    assert not out.exists()


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_rows_are_filled_by_kind_and_the_recorded_driver_solves_every_mission(hidden_corpus):
    entries = manifest(hidden_corpus)["scenarios"]
    assert len(entries) == 128 and sum(e["reactive"] for e in entries) == 71
    from_corpus = [e for e in entries if "source" in e]
    assert len(from_corpus) >= 20
    rows = [e for e in entries if e["family"] == "replay" and not e["reactive"]]
    # Each row keeps its kind: a corpus mission of kind K only in a row of kind K.
    kinds = [kind for kind, agents, count in REPLAYS for _ in range(count)]
    assert len(rows) == len(kinds)
    for row, kind in zip(rows, kinds, strict=True):
        if "source" in row:
            assert row["variant"].split("_", 1)[1] == kind, row
    assert {e["variant"].split("_", 1)[1] for e in from_corpus} >= {"cruise", "lane_change"}
    for e in from_corpus:
        assert verify_scenario(hidden_corpus / e["id"], hidden_corpus.parent).solved, e["id"]
        assert "<polygon" in draw_scenario(hidden_corpus / e["id"])  # every map draws


def _mission_source(scenario_dir: Path) -> tuple[str, str]:
    """(file, recorded vehicle) a corpus scenario was cut from, as its attribution says."""
    text = (scenario_dir / ATTRIBUTION_FILE).read_text()
    found = re.search(
        r"\(file `([^`]+)`\); the mission vehicle replaces recorded vehicle `(\w+)`", text
    )
    assert found, text
    return found.group(1), found.group(2)


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_no_recorded_vehicle_is_the_mission_of_two_scenarios(hidden_corpus, corpus_dir, cache_dir):
    """The split recording's two files share 16 vehicles under other ids and clocks, and the
    rotated copy all of its original's."""
    corpus = read_corpus(corpus_dir, cache_dir / "naturalistic")
    identities = [
        corpus.identity[_mission_source(hidden_corpus / e["id"])]
        for e in manifest(hidden_corpus)["scenarios"]
        if "source" in e
    ]
    assert len(identities) == len(set(identities))


@pytest.mark.slow
def test_split_recording_files_are_one_recording_sharing_vehicles(corpus_dir, cache_dir):
    corpus = read_corpus(corpus_dir, cache_dir / "naturalistic")
    merged = {k: v for k, v in corpus.identity.items() if k != v}
    split = {k: v for k, v in merged.items() if k[0].startswith("USA_Split")}
    assert len(split) >= 10
    for (file, vehicle), (first_file, first_vehicle) in split.items():
        assert (file, first_file) == ("USA_Split-1_2_T-1.xml", "USA_Split-1_1_T-1.xml")
        assert int(vehicle[2:]) == int(first_vehicle[2:]) + 900000  # how the split renumbered
    assert recording_location("USA_Split-1_2_T-1") == "USA_Split-1"
    # A copy of a file under another name holds the same vehicles, whatever it is called.
    copies = [k for k in corpus.identity if k[0] == "sim.xml"]
    assert len(copies) == 12
    for key in copies:
        assert corpus.identity[key] == corpus.identity[("USA_Truck-1_1_T-1.xml", key[1])]
    # Vehicles following each other in one lane are not merged: every vehicle of one file is
    # its own identity.
    for s in corpus.scenes:
        own = [corpus.identity[(s.file, t.vehicle_id)] for t in s.scene.trajectories]
        assert len(set(own)) == len(own)


@pytest.mark.slow
def test_a_long_truck_overlapping_a_car_rejects_both(corpus_dir, scenes_dir, cache_dir):
    car = "cr" + _first_vehicle(scenes_dir / cb.HIGHWAY_2018)
    scene = load_scene(corpus_dir / "USA_Truck-1_1_T-1.xml")
    truck = next(t for t in scene.trajectories if t.length == 20.0)
    by_id = {t.vehicle_id: t for t in scene.trajectories}
    assert collides(by_id[car], [truck]) == truck.vehicle_id
    corpus = read_corpus(corpus_dir, cache_dir / "naturalistic")
    (s,) = [s for s in corpus.scenes if s.scene.name == "USA_Truck-1_1_T-1"]
    assert s.rejected.get("collision", 0) >= 2
    assert {car, truck.vehicle_id}.isdisjoint(e.vehicle_id for e in s.egos)


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_provenance_comes_from_the_file(hidden_corpus):
    entries = manifest(hidden_corpus)["scenarios"]
    sources = {e["source"] for e in entries if "source" in e}
    assert "NGSIM" in sources
    for e in entries:
        if "source" not in e:
            continue
        scenario = load_scenario(hidden_corpus / e["id"])
        text = (hidden_corpus / e["id"] / ATTRIBUTION_FILE).read_text()
        if e["source"] == "NGSIM":
            assert scenario.label is DataLabel.naturalistic and e["variant"].startswith("ngsim_")
            assert "## Licence" in text and "BSD" in text  # LICENSE.txt beside the scenes
        else:
            assert e["source"] == SIMULATED and e["variant"].startswith("corpus_")
            assert scenario.label is DataLabel.recorded
            assert scenario.traffic.label is DataLabel.recorded


def test_attribution_says_below_only_with_a_licence_and_label_overrides(tmp_path, scenes_dir):
    folder = tmp_path / "nolicence"
    folder.mkdir()
    cb.copy_scene(
        scenes_dir / cb.HIGHWAY_2018, folder / "a.xml", "DEU_Sim-2_1_T-1", source=SIMULATED
    )
    scene = load_scene(folder / "a.xml")
    assert scene.provenance.label is DataLabel.recorded and scene.provenance.licence is None
    from scenarios.recorded.provenance import attribution

    text = attribution(scene.provenance, scene.name, "a.xml", "cr1")
    assert "below" not in text and "No licence file came with the scene" in text
    licence = tmp_path / "TERMS.txt"
    licence.write_text("Terms of the organiser's data.")
    stated = load_scene(folder / "a.xml", DataLabel.naturalistic, licence)
    assert stated.provenance.label is DataLabel.naturalistic
    text = attribution(stated.provenance, stated.name, "a.xml", "cr1")
    assert "below" in text and text.endswith("Terms of the organiser's data.")


@pytest.mark.slow
def test_the_seed_draws_from_all_candidates(corpus_dir, cache_dir, tmp_path):
    cruise = Spec(Family.replay, "cruise", None, 1, False)

    def drawn(seed: int) -> list[tuple[str, str]]:
        pool = NaturalisticPool.load(corpus_dir, "hidden", seed, cache_dir / "naturalistic")
        out = []
        for i in range(8):
            scenario, _ = pool.write(tmp_path / str(seed), "hidden", i, cruise, 1)
            out.append(scenario.missions[0].start)
        assert len(pool.used_scenes) > 1  # not the first file's vehicles one after another
        return out

    assert drawn(5) == drawn(5)
    assert drawn(5) != drawn(6)


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_manifest_lists_exactly_the_scenes_used_with_their_tracks(hidden_corpus, corpus_dir):
    """By file name and content: ``shifted.xml`` carries the shipped Lanker scene's id."""
    listed = manifest(hidden_corpus)["naturalistic_scenes"]
    cut_from = {
        _mission_source(hidden_corpus / e["id"])[0]
        for e in manifest(hidden_corpus)["scenarios"]
        if "source" in e
    }
    files = {s["file"] for s in listed}
    assert files == cut_from and len(listed) == len(files)
    assert {"shifted.xml", "USA_Lanker-1_1_T-1.xml"} <= files  # one benchmarkID, two files
    for s in listed:
        assert s["sha256"] == hashlib.sha256((corpus_dir / s["file"]).read_bytes()).hexdigest()
    assert not files & set(BROKEN)
    tracks = json.loads((hidden_corpus / TRACKS_FILE).read_text())
    assert set(tracks) == {s["file"] for s in listed}
    for s in listed:
        assert s["location"] and "tracks" not in s  # the manifest stays small
        scene = load_scene(corpus_dir / s["file"])
        assert {t["vehicle"] for t in tracks[s["file"]]} == {
            t.vehicle_id for t in scene.trajectories
        }


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_every_scene_is_drawn_in_its_local_frame_and_recorded_with_its_origin(
    hidden_corpus, corpus_dir
):
    listed = {s["file"]: s for s in manifest(hidden_corpus)["naturalistic_scenes"]}
    assert listed[GEO]["origin"] == list(UTM)
    for file, s in listed.items():
        assert s["origin"] == list(load_scene(corpus_dir / file).origin)
    from_geo = [
        e["id"]
        for e in manifest(hidden_corpus)["scenarios"]
        if "source" in e and _mission_source(hidden_corpus / e["id"])[0] == GEO
    ]
    assert from_geo  # and verified by the log replay expert with every corpus scenario
    for sid in from_geo:
        mission = load_scenario(hidden_corpus / sid).missions[0]
        assert max(abs(v) for v in (*mission.start[:2], *mission.goal.position)) < 1000.0
        assert "less (686000, 5335000) m" in (hidden_corpus / sid / ATTRIBUTION_FILE).read_text()


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_a_tram_is_left_out_and_a_motorcycle_is_traffic_only(hidden_corpus, corpus_dir):
    rejected = manifest(hidden_corpus)["naturalistic_rejected"]
    assert rejected["not_replayed"] == 1 and rejected["traffic_only"] == 1
    tram = load_scene(corpus_dir / "USA_Tram-1_1_T-1.xml")
    assert tram.left_out == {"train": 1}
    for e in manifest(hidden_corpus)["scenarios"]:
        if "source" not in e:
            continue
        traffic = read_trajectories(hidden_corpus / e["id"] / TRAJECTORIES_FILE)
        assert all(t.length != 15.0 for t in traffic.values()), e["id"]  # no tram replayed
        assert load_scenario(hidden_corpus / e["id"]).missions[0].vehicle.length != 2.2
    output = (hidden_corpus / "build-output.txt").read_text()
    assert "not_replayed: a train or tram, bicycle or pedestrian" in output


@pytest.mark.slow  # builds a whole hidden suite (the hidden_corpus fixture)
def test_build_output_counts_rejected_vehicles(hidden_corpus):
    rejected = manifest(hidden_corpus)["naturalistic_rejected"]
    assert rejected.get("collision", 0) >= 2 and rejected.get("short", 0) > 0
    assert (
        "recorded vehicles not used as missions" in (hidden_corpus / "build-output.txt").read_text()
    )
