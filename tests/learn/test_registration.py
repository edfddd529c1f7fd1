"""Registration with Gymnasium: the entry point pyproject declares, and a fresh interpreter."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import gymnasium

from learn.registration import ENV_ID
from tests.learn.conftest import PUBLIC

ROOT = Path(__file__).parents[2]


def test_the_declared_entry_point_registers_the_env() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    target = project["entry-points"]["gymnasium.envs"]["arena"]
    module, function = target.split(":")
    getattr(importlib.import_module(module), function)()
    assert ENV_ID == "arena/DrivingArena-v0" and ENV_ID in gymnasium.registry
    env = gymnasium.make(ENV_ID, suite=PUBLIC, scenario="p016_cruise_2lane_low")
    try:
        obs, info = env.reset(seed=0)
        assert info["scenario_id"] == "p016_cruise_2lane_low"
        assert env.observation_space.contains(obs)
    finally:
        env.close()


def test_a_fresh_interpreter_makes_the_env_by_name(short_road) -> None:
    code = (
        "import gymnasium\n"
        f"env = gymnasium.make('learn.registration:{ENV_ID}', suite={str(short_road)!r},"
        " action_space='Continuous')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(info['scenario_id'], env.step([1.0, 0.0, 0.0])[0]['ego_vehicle_state']['speed'])\n"
        "env.close()\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr
    scenario_id, speed = done.stdout.split()
    assert scenario_id == short_road.name and float(speed) > 0.0
