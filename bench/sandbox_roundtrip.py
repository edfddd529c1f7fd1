"""Benchmark: one ``act`` round trip, in-process vs process vs bubblewrap vs Docker, side by side.

A trivial policy (one constant action per agent) gets a realistic observation per the agent
interface: one agent, 4 waypoint paths x 50 waypoints, 20 neighbours. In-process calls the policy
object directly; every other column is the full evaluator path (pickle the observation, frame,
write, the runner decodes, calls the policy, answers in JSON, we decode).

    python bench/sandbox_roundtrip.py [--steps 2000] [--kinds process,bubblewrap,docker]

The last line is ``docker_median_ms=<m> bwrap_median_ms=<m> docker_ratio=<docker/in-process>``.
Target: Docker median round trip under 0.3 ms.
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
import time
from pathlib import Path

import numpy as np

from arena.config import SandboxKind, Settings
from evaluator.sandbox import backend, start
from submissions.intake import prepare_submission
from submissions.sample import sample_observation

TRIVIAL_POLICY = """
class Policy:
    def act(self, obs):
        return {agent_id: [10.0, 0.0] for agent_id in obs}
"""
WARMUP = 200


def timings_ms(act, obs: dict, steps: int) -> np.ndarray:
    for _ in range(WARMUP):
        act(obs)
    times = np.empty(steps)
    for i in range(steps):
        started = time.perf_counter()
        act(obs)
        times[i] = time.perf_counter() - started
    return times * 1000.0


def in_process_act(folder: Path):
    spec = importlib.util.spec_from_file_location("bench_policy", folder / "policy.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Policy().act


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--kinds", default="process,bubblewrap,docker")
    args = parser.parse_args()

    base = Path(tempfile.mkdtemp(prefix="arena-bench-"))
    settings = Settings(data_dir=base / "data")
    source = base / "src"
    source.mkdir()
    (source / "policy.py").write_text(TRIVIAL_POLICY)
    submission = prepare_submission(source, base / "submission", settings)
    obs = sample_observation()

    results: dict[str, np.ndarray] = {
        "in-process": timings_ms(in_process_act(source), obs, args.steps)
    }
    for name in args.kinds.split(","):
        kind = SandboxKind(name)
        reason = backend(kind).unavailable_reason(settings)
        if reason:
            print(f"{name}: skipped ({reason})")
            continue
        with start(
            submission, kind=kind, settings=settings, labels={"bench": "roundtrip"}
        ) as handle:
            results[name] = timings_ms(handle.act, obs, args.steps)

    print(f"act round trip, {args.steps} steps, observation of 4 x 50 waypoints + 20 neighbours")
    print(f"{'':>12} {'median ms':>10} {'p99 ms':>10} {'x in-process':>13}")
    baseline = float(np.median(results["in-process"]))
    for name, times in results.items():
        median = float(np.median(times))
        print(
            f"{name:>12} {median:>10.4f} {np.percentile(times, 99):>10.4f} "
            f"{median / baseline:>13.1f}"
        )
    docker = float(np.median(results["docker"])) if "docker" in results else float("nan")
    bwrap = float(np.median(results["bubblewrap"])) if "bubblewrap" in results else float("nan")
    ratio = docker / baseline
    print(f"docker_median_ms={docker:.4f} bwrap_median_ms={bwrap:.4f} docker_ratio={ratio:.1f}")


if __name__ == "__main__":
    main()
