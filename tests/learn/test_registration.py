"""Registration with Gymnasium: the start-up hook every wheel carries, and a fresh interpreter
making the env by its plain id without importing anything of ours."""

from __future__ import annotations

import base64
import hashlib
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium
import pytest

from learn.registration import ENV_ID
from tests.learn.conftest import PUBLIC

ROOT = Path(__file__).parents[2]


def test_the_registered_env_resets_into_its_space() -> None:
    import learn.registration  # noqa: F401 (registers, as the start-up hook does)

    assert ENV_ID == "arena/DrivingArena-v0" and ENV_ID in gymnasium.registry
    env = gymnasium.make(ENV_ID, suite=PUBLIC, scenario="p016_cruise_2lane_low")
    try:
        obs, info = env.reset(seed=0)
        assert info["scenario_id"] == "p016_cruise_2lane_low"
        assert env.observation_space.contains(obs)
    finally:
        env.close()


# Slow: the build compiles the simulator's core (setup.py), about 25 CPU seconds, a sixth of the
# whole fast tier; the integration tier runs it.
@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")  # setuptools says it builds an editable wheel
def test_every_wheel_carries_the_start_up_hook(tmp_path) -> None:
    # In an interpreter of its own, as pip runs a build backend: setuptools refuses to load
    # where another test already imported the standard library's distutils.
    build = (
        "import sys; sys.path.insert(0, sys.argv[1]); import driving_arena_build as backend; "
        "print(backend.build_editable(sys.argv[2]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", build, str(ROOT / "build_backend"), str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    name = done.stdout.split()[-1]
    with zipfile.ZipFile(tmp_path / name) as wheel:
        hook = wheel.read("driving_arena_gymnasium.pth")
        record = next(n for n in wheel.namelist() if n.endswith(".dist-info/RECORD"))
        lines = wheel.read(record).decode().splitlines()
    digest = base64.urlsafe_b64encode(hashlib.sha256(hook).digest()).rstrip(b"=").decode()
    assert f"driving_arena_gymnasium.pth,sha256={digest},{len(hook)}" in lines
    assert hook.decode().startswith("import learn.gymnasium_hook")


@pytest.mark.slow
def test_a_fresh_interpreter_makes_the_env_by_name(short_road, tmp_path) -> None:
    code = (
        "import gymnasium\n"
        f"env = gymnasium.make({ENV_ID!r}, suite={str(short_road)!r},"
        " action_space='Continuous')\n"
        "obs, info = env.reset(seed=0)\n"
        "speed = env.step([1.0, 0.0, 0.0])[0]['ego_vehicle_state']['speed'].item()\n"
        "print(info['scenario_id'], speed)\n"
        "env.close()\n"
    )
    # The installed package, as a user has it: no PYTHONPATH, run from outside the checkout.
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    scenario_id, speed = done.stdout.split()
    assert scenario_id == short_road.name and float(speed) > 0.0
