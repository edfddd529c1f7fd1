"""Benchmarks cannot rot: every ``bench/*.py`` runs in its smoke mode (seconds, tiny sizes) as a
user runs it (``python bench/NAME.py --smoke``, from anywhere: nothing of the checkout on the
path but the script's folder), and imports nothing from ``tests/``. ``bench/_*.py`` are the
benchmarks' shared helpers, not benchmarks."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
SCRIPTS = sorted(p.name for p in BENCH.glob("*.py") if not p.name.startswith("_"))
# The smoke runs that start the service, its daemons or Docker: minutes, not seconds.
HEAVY = {"deploy_compose.py", "faults.py", "hostile_uploads.py", "stacks.py"}


def test_every_benchmark_is_found():
    assert {"faults.py", "api_load.py", "sim_throughput.py"} <= set(SCRIPTS)


@pytest.mark.parametrize("name", SCRIPTS)
def test_a_benchmark_imports_nothing_from_the_tests(name):
    tree = ast.parse((BENCH / name).read_text())
    imported = [
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    ]
    imported += [
        node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module
    ]
    assert not [m for m in imported if m == "tests" or m.startswith("tests.")], name
    assert "--smoke" in (BENCH / name).read_text(), f"{name} has no --smoke mode"


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.docker) if n in HEAVY else n for n in SCRIPTS]
)
def test_a_benchmark_runs_in_its_smoke_mode(name, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [sys.executable, str(BENCH / name), "--smoke"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, f"{name}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
