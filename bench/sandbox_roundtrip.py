"""Benchmark: one ``act`` round trip, in-process vs process vs bubblewrap vs Docker, side by side.

A trivial policy (one constant action per agent) gets a realistic observation per the agent
interface: one agent, 4 waypoint paths x 50 waypoints, 20 neighbours. In-process calls the policy
object directly; every other row is the full evaluator path (pickle the observation, frame,
write, the runner decodes, calls the policy, answers in JSON, we decode). ``docker (forked)`` is
an agent forked in a warm Docker sandbox, as evaluations run them (docs/protocol.md). The
``floor`` column is the same round trip with an empty observation: what the transport alone
costs, the rest of the median is encoding and decoding the observation.

    python bench/sandbox_roundtrip.py [--steps 2000] [--kinds process,bubblewrap,docker]

The last line is ``docker_median_ms=<m> bwrap_median_ms=<m> docker_ratio=<docker/in-process>
docker_floor_ms=<m>``. Target: Docker median round trip at most 0.1 ms.
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
from evaluator.sandbox.warm import WarmAgent
from submissions.intake import prepare_submission
from submissions.sample import sample_observation

TRIVIAL_POLICY = """
class Policy:
    def act(self, obs):
        return {agent_id: [10.0, 0.0] for agent_id in obs}
"""
WARMUP = 200
EMPTY = {"Agent_0": {}}


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

    results: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    in_process = in_process_act(source)
    results["in-process"] = (
        timings_ms(in_process, obs, args.steps),
        timings_ms(in_process, EMPTY, args.steps),
    )
    labels = {"bench": "roundtrip"}
    for name in args.kinds.split(","):
        kind = SandboxKind(name)
        reason = backend(kind).unavailable_reason(settings)
        if reason:
            print(f"{name}: skipped ({reason})")
            continue
        with start(submission, kind=kind, settings=settings, labels=labels) as handle:
            results[name] = both(handle.act, obs, args.steps)
        if kind is SandboxKind.docker:
            warm = WarmAgent.start(submission, kind, settings, labels=labels)
            forked = warm.fork(settings, labels)
            try:
                with forked.start() as handle:
                    results["docker (forked)"] = both(handle.act, obs, args.steps)
            finally:
                forked.close()
                warm.close()

    print(f"act round trip, {args.steps} steps, observation of 4 x 50 waypoints + 20 neighbours")
    print(f"{'':>16} {'median ms':>10} {'p99 ms':>10} {'x in-process':>13} {'floor ms':>9}")
    baseline = float(np.median(results["in-process"][0]))
    for name, (times, floor) in results.items():
        median = float(np.median(times))
        print(
            f"{name:>16} {median:>10.4f} {np.percentile(times, 99):>10.4f} "
            f"{median / baseline:>13.1f} {np.median(floor):>9.4f}"
        )
    docker = median_of(results, "docker")
    bwrap = median_of(results, "bubblewrap")
    floor = float(np.median(results["docker"][1])) if "docker" in results else float("nan")
    print(
        f"docker_median_ms={docker:.4f} bwrap_median_ms={bwrap:.4f} "
        f"docker_ratio={docker / baseline:.1f} docker_floor_ms={floor:.4f}"
    )


def both(act, obs: dict, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Round trips with ``obs`` and with an empty observation [ms]."""
    return timings_ms(act, obs, steps), timings_ms(act, EMPTY, steps)


def median_of(results: dict, name: str) -> float:
    return float(np.median(results[name][0])) if name in results else float("nan")


if __name__ == "__main__":
    main()
