"""`arena init`: the starting agent folder is runnable, its own test passes, and it drives."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from arena_command import app
from tests.cli_runner import CliRunner

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_init_writes_an_agent_whose_own_test_passes(tmp_path):
    folder = tmp_path / "my_agent"
    result = CliRunner().invoke(app, ["init", str(folder)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in folder.iterdir()) == ["agent.yaml", "policy.py", "test_policy.py"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(folder)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "1 passed" in run.stdout


@pytest.mark.slow
def test_init_test_catches_a_broken_policy(tmp_path):
    folder = tmp_path / "my_agent"
    CliRunner().invoke(app, ["init", str(folder)])
    policy = folder / "policy.py"
    policy.write_text(policy.read_text().replace("[target_speed(agent_obs), 0.0]", "[1.0]"))
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(folder)],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 1


def test_init_refuses_a_folder_with_files(tmp_path):
    (tmp_path / "policy.py").write_text("mine")
    result = CliRunner().invoke(app, ["init", str(tmp_path)])
    assert result.exit_code == 1
    assert (tmp_path / "policy.py").read_text() == "mine"


@pytest.mark.slow
def test_the_starting_agent_drives_a_public_scenario(tmp_path):
    folder = tmp_path / "my_agent"
    CliRunner().invoke(app, ["init", str(folder)])
    out = tmp_path / "results"
    result = CliRunner().invoke(
        app,
        [
            "evaluate",
            str(folder),
            "--scenario",
            "p000_left_turn_t_low",
            "--sandbox",
            "process",
            "--out",
            str(out),
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["scenarios"][0]["status"] == "done"
