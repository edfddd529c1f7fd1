"""Benchmark: the whole hidden suite (development seed), planner agent, Docker sandbox, with one
and with two parallel jobs, measured side by side in one run.

    python bench/evaluate_suite.py [--sandbox docker] [--keep DIR]

Prints wall times and simulated steps per second; the last line is
``wall_s=<jobs 2 wall time> speedup=<jobs 1 wall / jobs 2 wall>``.
Targets: wall_s < 120 on a 2-core machine, speedup >= 1.8.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from arena.config import SandboxKind, get_settings
from evaluator.runner import evaluate
from evaluator.runner.evaluate import TIMINGS_FILE

REPO = Path(__file__).resolve().parents[1]
PLANNER = REPO / "submissions" / "examples" / "planner"


def build_hidden_suite(out: Path, seed: int) -> None:
    command = [sys.executable, "-c", "from arena.cli import app; app()", "scenarios", "build"]
    command += ["--suite", "hidden", "--seed", str(seed), "--out", str(out)]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)


def timed_evaluation(suite: Path, out: Path, jobs: int, sandbox: SandboxKind) -> tuple[float, int]:
    started = time.perf_counter()
    summary = evaluate(PLANNER, suite, out_dir=out, jobs=jobs, sandbox=sandbox)
    wall = time.perf_counter() - started
    if summary.uncharged:
        print(f"  warning: uncharged scenarios {', '.join(summary.uncharged)}", file=sys.stderr)
    steps = sum(entry.steps for entry in summary.scenarios)
    completion = summary.metrics.completion if summary.metrics else float("nan")
    # Sum of per-scenario wall times: above jobs x wall means episodes slowed each other down.
    busy = sum(json.loads((out / TIMINGS_FILE).read_text()).values())
    print(
        f"jobs={jobs}: {len(summary.scenarios)} scenarios in {wall:.1f} s, {steps} episode steps, "
        f"{steps / wall:.0f} steps/s, scenario time sum {busy:.0f} s, "
        f"completion={completion:.3f}, load average {os.getloadavg()[0]:.1f}"
    )
    return wall, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sandbox", type=SandboxKind, default=SandboxKind.docker)
    parser.add_argument("--keep", type=Path, help="keep the suite and results here (new dir)")
    args = parser.parse_args()
    if args.keep and args.keep.exists():
        parser.error(f"{args.keep} exists: results there would be resumed, not timed")
    seed = get_settings().development_seed
    with tempfile.TemporaryDirectory(prefix="arena-bench-") as tmp:
        work = args.keep or Path(tmp)
        suite = work / "hidden-suite"
        started = time.perf_counter()
        build_hidden_suite(suite, seed)
        print(f"built hidden suite (seed {seed}) in {time.perf_counter() - started:.1f} s")
        wall_1, _ = timed_evaluation(suite, work / "jobs1", 1, args.sandbox)
        wall_2, _ = timed_evaluation(suite, work / "jobs2", 2, args.sandbox)
    print(f"wall_s={wall_2:.1f} speedup={wall_1 / wall_2:.2f}")


if __name__ == "__main__":
    main()
