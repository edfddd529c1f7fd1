"""Training-environment throughput: raw libsumo vs our Gymnasium env, without and with rasters.

The traffic of ``bench/sim_throughput.py`` (a 3-lane, 3 km straight road, 100 background
vehicles, steps of 0.1 s). Four sides, in one run: raw libsumo stepping that traffic
(``simulationStep`` only, in its own process); :class:`learn.gym_env.DrivingArenaEnv` with one
ego driven by a gap-keeping policy (TargetPose), no rasters, its simulator in this process (the
default when nothing else simulates here); the same env with all three rasters at 256 px; and,
for comparison, the env without rasters with its simulator in a child process
(``simulator="subprocess"``: the pipe and packing on top). The env sides time ``env.step`` as a
training loop sees it (simulator, observation encoding, scoring terms, reward); the policy's own
time is not counted. Best of ``--repeat`` each. A fifth side is the env without rasters with the
simulator's pure-Python reference instead of its compiled core (``ARENA_PURE_PYTHON=1``,
``sim/compiled.py``), in a process of its own (the switch is read at import).

Two clocks: wall time, and CPU time (this process's plus any simulator child's, from ``/proc``).
On a shared, loaded machine wall time mostly measures the neighbours; the summary line uses CPU
time, which counts only the work done.

Usage: ``python bench/env_throughput.py [--steps 1000] [--vehicles 100] [--repeat 2]``.
The last line printed is ``env_ratio=<env_time/raw_time> raster_ms=<extra ms per agent-step for
rasters> pure_env_ratio=<pure-Python env_time/raw_time> compiled_speedup=<pure-Python env_time /
env_time>`` (targets: env_ratio at most 2.5, raster_ms at most 1).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _prerequisites import module, require, tool
from sim_throughput import build, in_child, raw_side

from learn.gym_env import DrivingArenaEnv
from learn.worker import SimulatorProcess
from sim.compiled import core_status

RASTERS = {"top_down_rgb": True, "occupancy_grid_map": True, "drivable_area_grid_map": True}


def follow_gap(obs: dict) -> np.ndarray:
    """TargetPose along the lane, slowing for the nearest vehicle ahead in it (encoded obs)."""
    x, y, _ = obs["ego_vehicle_state"]["position"]
    nbr = obs["neighborhood_vehicle_states"]
    pos = nbr["position"]
    ahead = (nbr["mask"] > 0) & (pos[:, 0] > x) & (np.abs(pos[:, 1] - y) < 1.6)
    gap = float((pos[ahead, 0] - x).min()) if ahead.any() else 100.0
    speed = min(25.0, max(0.0, (gap - 10.0) / 1.5))
    return np.array([x + speed * 0.1, y, 0.0, 0.1], np.float32)


def env_side(
    folder: Path, steps: int, rasters: bool, simulator: str = "auto"
) -> tuple[float, float]:
    """(wall, CPU) seconds spent in ``env.step`` over ``steps`` steps (policy excluded)."""
    options = {**RASTERS, "img_pixels": 256} if rasters else {}
    # follow_gap sends TargetPose actions (the environments' default is LaneWithContinuousSpeed).
    env = DrivingArenaEnv(folder, simulator=simulator, action_space="TargetPose", **options)
    try:
        obs, _ = env.reset(seed=0)
        # A simulator in a child process (simulator="subprocess") uses CPU there too.
        child = env._simulator if isinstance(env._simulator, SimulatorProcess) else None
        wall = cpu = 0.0
        child_cpu = child.cpu_seconds() if child else 0.0
        for _ in range(steps):
            action = follow_gap(obs)
            t0, c0 = time.perf_counter(), time.process_time()
            obs, _, terminated, truncated, info = env.step(action)
            wall += time.perf_counter() - t0
            cpu += time.process_time() - c0
            if terminated or truncated:
                raise SystemExit(f"the ego must drive the whole run: {info['done_reason']}")
        if child:
            cpu += child.cpu_seconds() - child_cpu
    finally:
        env.close()
    return wall, cpu


def env_side_in_child(folder: str, steps: int, queue) -> None:
    """:func:`env_side` without rasters in a process of its own (``sim_throughput.in_child``)."""
    queue.put((env_side(Path(folder), steps, rasters=False), ""))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--smoke", action="store_true", help="20 steps, 5 vehicles, once")
    args = parser.parse_args()
    if args.smoke:
        args.steps, args.vehicles, args.repeat = 20, 5, 1
    require(
        tool("netconvert", "apt-get install sumo (or pip install eclipse-sumo)"),
        module("libsumo", "pip install libsumo (the project's dependencies)"),
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = build(Path(tmp) / "bench", args.vehicles, args.steps)
        print(f"simulator core: {core_status()}")
        raw, plain, raster, child, pure = [], [], [], [], []
        for _ in range(args.repeat):
            raw.append(in_child(raw_side, str(folder), args.steps)[0])
            plain.append(env_side(folder, args.steps, rasters=False))
            raster.append(env_side(folder, args.steps, rasters=True))
            child.append(env_side(folder, args.steps, rasters=False, simulator="subprocess"))
            pure.append(in_child(env_side_in_child, str(folder), args.steps, pure_python=True)[0])
    n = args.steps
    sides = (
        ("raw libsumo", raw),
        ("env", plain),
        ("env+rasters", raster),
        ("env (child)", child),
        ("env (pure Python)", pure),
    )
    best = {name: (min(w for w, _ in runs), min(c for _, c in runs)) for name, runs in sides}
    for name, (wall, cpu) in best.items():
        print(
            f"{name + ':':19s} wall {n / wall:7,.0f} steps/s ({wall * 1e3 / n:.3f} ms/step)"
            f"   CPU {n / cpu:7,.0f} steps/s ({cpu * 1e3 / n:.3f} ms/step)"
        )
    raster_ms = (best["env+rasters"][1] - best["env"][1]) * 1e3 / n
    raw, env, pure = best["raw libsumo"][1], best["env"][1], best["env (pure Python)"][1]
    print(
        f"env_ratio={env / raw:.2f} raster_ms={raster_ms:.3f} pure_env_ratio={pure / raw:.2f}"
        f" compiled_speedup={pure / env:.2f}"
    )


if __name__ == "__main__":
    main()
