"""`arena scenarios build --suite hidden --naturalistic-dir DIR`: the hidden suite's one-agent
replays come from the organiser's scenes; a malformed scene file stops the build, named."""

from __future__ import annotations

import hashlib
import shutil

import pytest
from typer.testing import CliRunner

from arena.cli import app
from arena.config import get_settings
from arena.scenario import DataLabel, load_scenario
from scenarios.suites import build_suite
from tests.scenarios.conftest import manifest

runner = CliRunner()


@pytest.fixture(scope="module")
def hidden_natural(tmp_path_factory, cache_dir, scenes_dir):
    out = tmp_path_factory.mktemp("hidden-natural") / "suite"
    build_suite(
        "hidden", get_settings().development_seed, out, cache_dir, naturalistic_dir=scenes_dir
    )
    return out


@pytest.mark.slow
def test_hidden_suite_draws_its_one_agent_replays_from_the_scenes(hidden_natural):
    entries = manifest(hidden_natural)["scenarios"]
    assert len(entries) == 128 and sum(e["reactive"] for e in entries) == 71
    natural = [e for e in entries if e["label"] == "naturalistic"]
    # 51 one-agent non-reactive replay rows; the shipped scenes hold 52 ego choices.
    assert len(natural) == 51
    assert all(
        e["family"] == "replay"
        and not e["reactive"]
        and e["agents"] == 1
        and e["variant"].startswith("ngsim_")
        and e["source"] == "NGSIM"
        for e in natural
    )
    recorded = [e for e in entries if e["label"] == "recorded"]
    assert {(e["agents"], e["reactive"]) for e in recorded} == {(2, False), (1, True)}
    assert all("source" not in e for e in entries if e["label"] != "naturalistic")
    starts = set()
    for e in natural:
        scenario = load_scenario(hidden_natural / e["id"])
        assert scenario.label is DataLabel.naturalistic
        assert scenario.traffic.label is DataLabel.naturalistic
        assert (hidden_natural / e["id"] / "ATTRIBUTION.md").exists()
        starts.add((scenario.missions[0].start, scenario.missions[0].goal.position))
    assert len(starts) == len(natural)  # no ego choice used twice


def test_manifest_names_the_scene_files_read(hidden_natural, scenes_dir):
    listed = manifest(hidden_natural)["naturalistic_scenes"]
    assert sorted(s["file"] for s in listed) == sorted(p.name for p in scenes_dir.glob("*.xml"))
    for s in listed:
        assert s["sha256"] == hashlib.sha256((scenes_dir / s["file"]).read_bytes()).hexdigest()


def test_build_rejects_a_malformed_scene_naming_file_and_problem(tmp_path, scenes_dir):
    folder = tmp_path / "scenes"
    shutil.copytree(scenes_dir, folder)
    text = (folder / "USA_Peach-4_8_T-1.xml").read_text()
    (folder / "USA_Peach-4_8_T-1.xml").write_text(text.replace("<x>", "<x>abc", 1))
    out = tmp_path / "hidden"
    result = runner.invoke(
        app,
        [
            "scenarios",
            "build",
            "--suite",
            "hidden",
            "--dev",
            "--out",
            str(out),
            "--naturalistic-dir",
            str(folder),
        ],
        env={"COLUMNS": "400"},
    )
    assert result.exit_code != 0
    text = "".join(result.output.replace("│", "").split())  # undo rich's error box wrapping
    assert "USA_Peach-4_8_T-1.xml:malformedCommonRoad2020a" in text
    assert "couldnotconvertstringtofloat:'abc" in text  # the problem
    assert not out.exists()
