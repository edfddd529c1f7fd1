"""bench/stacks.py's smoke mode: a stack and two uploads through the resolver sandbox, against
a package index on loopback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench" / "stacks.py"


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_the_stacks_benchmark_smoke_run() -> None:
    run = subprocess.run(
        [sys.executable, str(BENCH), "--smoke"], capture_output=True, text=True, timeout=600
    )
    assert run.returncode == 0, run.stdout + run.stderr
    last = run.stdout.strip().splitlines()[-1]
    assert "stack_upload=ok" in last and "torch_build=2.1.0+cpu" in last
