from __future__ import annotations

import json
import shutil
import sys

import pytest

from arena.suite import SHIPPED_PUBLIC_DIR
from arena_command import app
from tests.cli_runner import CliRunner

runner = CliRunner()
ARENA_COMMAND = [sys.executable, "-c", "from arena_command import app; app()"]


def test_build_hidden_refuses_without_a_seed(tmp_path, monkeypatch):
    monkeypatch.delenv("ARENA_HIDDEN_SEED", raising=False)
    from arena.config import get_settings

    get_settings.cache_clear()
    result = runner.invoke(
        app, ["scenarios", "build", "--suite", "hidden", "--out", str(tmp_path / "h")]
    )
    assert result.exit_code != 0
    assert "--dev" in result.output
    assert not (tmp_path / "h").exists()


def test_public_build_refuses_a_seed(tmp_path):
    result = runner.invoke(
        app,
        ["scenarios", "build", "--suite", "public", "--seed", "3", "--out", str(tmp_path / "p")],
    )
    assert result.exit_code != 0


@pytest.mark.slow
def test_list_show_and_verify_on_a_copy_of_the_public_set(tmp_path):
    suite = tmp_path / "public"
    shutil.copytree(SHIPPED_PUBLIC_DIR, suite)
    listed = runner.invoke(app, ["scenarios", "list", str(suite)])
    assert listed.exit_code == 0, listed.output
    assert "p000" in listed.output

    replay = next(p.name for p in sorted(suite.iterdir()) if "replay_cut_off" in p.name)
    svg = tmp_path / "replay.svg"
    shown = runner.invoke(
        app,
        ["scenarios", "show", replay, "--suite-dir", str(suite), "--step", "30", "--out", str(svg)],
    )
    assert shown.exit_code == 0, shown.output
    text = svg.read_text()
    assert text.startswith("<svg") and text.count("<polygon") > 20 and "goal Agent_0" in text

    verified = runner.invoke(app, ["scenarios", "verify", str(suite), "--only", replay])
    assert verified.exit_code == 0, verified.output
    assert verified.output.strip().splitlines()[-1] == "solved=1/1"
    entry = next(
        e
        for e in json.loads((suite / "manifest.json").read_text())["scenarios"]
        if e["id"] == replay
    )
    assert entry["unsolvable_reason"] is None


def test_list_of_a_folder_without_manifest_is_a_clear_error(tmp_path):
    result = runner.invoke(app, ["scenarios", "list", str(tmp_path)])
    assert result.exit_code != 0
    assert "manifest.json" in result.output


def test_show_reactive_scenario_simulates_to_the_step(tmp_path):
    suite = SHIPPED_PUBLIC_DIR
    sid = next(p.name for p in sorted(suite.iterdir()) if "left_turn_t" in p.name)
    svg = tmp_path / "t.svg"
    result = runner.invoke(app, ["scenarios", "show", sid, "--step", "60", "--out", str(svg)])
    assert result.exit_code == 0, result.output
    assert "step 60" in svg.read_text()


def test_an_empty_seed_is_refused_with_what_a_seed_may_be(tmp_path):
    result = runner.invoke(
        app,
        ["scenarios", "build", "--suite", "hidden", "--seed", " ", "--out", str(tmp_path / "h")],
    )
    assert result.exit_code != 0
    assert "number or a passphrase" in result.output


# A real `arena` process running the planner's episode in a pipe: the fast tier starts none.
@pytest.mark.integration
def test_verify_in_a_pipe_is_not_cut_at_80_columns(tmp_path):
    """Output piped (`arena scenarios verify ... | tee log`): each row whole on one line."""
    import os
    import subprocess

    suite = tmp_path / "public"
    shutil.copytree(SHIPPED_PUBLIC_DIR, suite)
    longest = max((p.name for p in suite.iterdir() if p.is_dir()), key=len)
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    done = subprocess.run(
        [*ARENA_COMMAND, "scenarios", "verify", str(suite), "--only", longest],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    row = next(
        line for line in done.stdout.splitlines() if line.startswith("│") and longest in line
    )
    assert "…" not in done.stdout
    assert row.split("│")[1].strip() == longest  # the id cell whole, on its own line
