"""The example agents are found where they are: the checkout's ``examples/``, or the copy an
installed (non-editable) wheel carries, from which the service runs its reference planner."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from arena.examples import example_dir, examples_dir
from tests.packages import ALL

ROOT = Path(__file__).resolve().parents[2]
INSTALLED = "share/driving-arena/examples"


def example_files() -> list[str]:
    """Every file of every example, relative to ``examples/`` (no byte code)."""
    return sorted(
        path.relative_to(ROOT / "examples").as_posix()
        for path in (ROOT / "examples").rglob("*")
        if path.is_file() and "__pycache__" not in path.parts
    )


def test_a_checkout_finds_the_folder_beside_the_packages() -> None:
    assert examples_dir() == ROOT / "examples"
    assert (example_dir("planner") / "policy.py").is_file()
    assert not (ROOT / "submissions" / "examples").exists()  # in no package of ours


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A regular wheel built from a copy of the sources (the build writes into its tree)."""
    source = tmp_path_factory.mktemp("source")
    for path in ROOT.iterdir():
        if path.is_file():  # pyproject.toml, README.md, setup.py, ...
            shutil.copy(path, source / path.name)
    for name in ("build_backend", "examples", *ALL):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("wheel")
    # In an interpreter of its own, as pip runs a build backend (see tests/learn/test_registration).
    build = (
        "import sys; sys.path.insert(0, 'build_backend'); import driving_arena_build as backend; "
        "print(backend.build_wheel(sys.argv[1]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", build, str(out)],
        capture_output=True,
        text=True,
        cwd=source,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return out / done.stdout.split()[-1]


@pytest.mark.slow  # builds and installs a wheel
def test_the_wheel_carries_every_example_file_as_data(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    data = sorted(n.split(f"/data/{INSTALLED}/", 1)[1] for n in names if f"/data/{INSTALLED}/" in n)
    assert data == example_files()
    assert not [n for n in names if n.startswith("examples/")]  # no top-level package of that name


@pytest.mark.slow  # builds and installs a wheel
def test_an_installed_wheel_runs_the_reference_planner_from_its_copy(wheel, tmp_path) -> None:
    prefix = tmp_path / "prefix"
    install = [sys.executable, "-m", "pip", "install", "--no-deps", "--no-index"]
    done = subprocess.run(
        [*install, "--ignore-installed", "--prefix", str(prefix), str(wheel)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    site = sysconfig.get_path("purelib", vars={"base": str(prefix), "platbase": str(prefix)})
    code = (
        "from arena.examples import examples_dir\n"
        "from scenarios.experts import PlannerAgent, planner_interface\n"
        "import scenarios\n"
        "PlannerAgent()\n"
        "print(scenarios.__file__, examples_dir(), planner_interface().action_space.name)\n"
    )
    # The installed package alone: the checkout is neither the working folder nor on the path
    # (the dependencies still come from this interpreter's own site-packages).
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = site
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    module, found, action_space = done.stdout.split()
    assert Path(module).is_relative_to(prefix)
    assert Path(found) == (prefix / INSTALLED).resolve()
    assert sorted(p.name for p in Path(found).iterdir()) == sorted(
        p.name for p in (ROOT / "examples").iterdir() if p.is_dir() and p.name != "__pycache__"
    )
    assert action_space == "TargetPose"
