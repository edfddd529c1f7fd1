"""Training-environment throughput: raw libsumo vs our Gymnasium env, without and with rasters.

The traffic of ``bench/sim_throughput.py`` (a 3-lane, 3 km straight road, 100 background
vehicles, steps of 0.1 s). Three sides, in one run: raw libsumo stepping that traffic
(``simulationStep`` only, in its own process); :class:`learn.gym_env.DrivingArenaEnv` with one
ego driven by a gap-keeping policy (TargetPose), no rasters; and the same env with all three
rasters at 256 px. The env sides time ``env.step`` as a training loop sees it (the simulator
child, the pipe, observation encoding); the policy's own time is not counted. Best of
``--repeat`` each.

Usage: ``python bench/env_throughput.py [--steps 1000] [--vehicles 100] [--repeat 2]``.
The last line printed is ``env_ratio=<env_time/raw_time> raster_ms=<extra ms per agent-step for
rasters>`` (targets: at most 2 and at most 1).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from sim_throughput import build, in_child, raw_side

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


def env_side(folder: Path, steps: int, rasters: bool) -> float:
    """Seconds spent in ``env.step`` over ``steps`` steps (policy excluded)."""
    from learn.gym_env import DrivingArenaEnv

    options = {**RASTERS, "img_pixels": 256} if rasters else {}
    env = DrivingArenaEnv(folder, **options)
    try:
        obs, _ = env.reset(seed=0)
        in_step = 0.0
        for _ in range(steps):
            action = follow_gap(obs)
            t0 = time.perf_counter()
            obs, _, terminated, truncated, info = env.step(action)
            in_step += time.perf_counter() - t0
            if terminated or truncated:
                raise SystemExit(f"the ego must drive the whole run: {info['done_reason']}")
    finally:
        env.close()
    return in_step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = build(Path(tmp) / "bench", args.vehicles, args.steps)
        raw, plain, raster = [], [], []
        for _ in range(args.repeat):
            raw.append(in_child(raw_side, str(folder), args.steps)[0])
            plain.append(env_side(folder, args.steps, rasters=False))
            raster.append(env_side(folder, args.steps, rasters=True))
    n = args.steps
    for name, t in (("raw libsumo", min(raw)), ("env", min(plain)), ("env+rasters", min(raster))):
        print(f"{name + ':':13s}{n / t:8,.0f} steps/s ({t * 1e3 / n:.3f} ms/step)")
    raster_ms = (min(raster) - min(plain)) * 1e3 / n
    print(f"env_ratio={min(plain) / min(raw):.2f} raster_ms={raster_ms:.3f}")


if __name__ == "__main__":
    main()
