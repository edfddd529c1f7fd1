"""What the environments return must not change with speed work on them.

Every value a training loop gets from ``reset``, ``step`` and ``render``: each observation array
(dtype, shape, bytes, writable, contiguous), rewards, terminations, truncations and infos (keys
in order, values with their types), hashed per episode. The episodes: the Gymnasium env with all
rasters and its picture on a cruise, with TargetPose through cut-in traffic (the closeness
terms), into a collision (a terminal observation) and to the step limit, in this process and in
a child process; the PettingZoo env with three agents joining and leaving a shared road. The
digests were taken on the code before the per-step speed work of ``learn/`` (issue 28); a
deliberate change of what the environments return updates them in the same commit, saying why:
``python -m tests.learn.test_env_regression`` prints the current digests. The last such change
made scalars arrays of shape ``(1,)`` instead of ``()``: the digests of the code before it, with
``()`` hashed as ``(1,)``, equal these, so no value moved.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from learn.gym_env import DrivingArenaEnv
from learn.parallel_env import DrivingArenaParallelEnv
from tests.learn.conftest import PUBLIC
from tests.sim.builders import ScenarioSpec, lane_y, make_scenario, mission, vehicle_xml

EXPECTED = {
    "cruise_rasters": "cad0e91027a3a2101eaa3c013fb91c0968f0afb6e872ce1b2b61a60942e9a9ec",
    "cut_in_target_pose": "56371177564f62f2d5f413f54a132b14ab12a05b81a3a04246d6aa7ae49225ab",
    "collision": "3413af66e9e05ebef510cab5b7ecd5767ef3aa26f132e22bd168aeb9b2a16b6e",
    "step_limit_child": "8690977e7489e2cda4d0127d4aaf3ac5441227cc6aca4e1bb1aa879662b71065",
    "three_agents": "ceb79b4a5ef89f23b5a9927a7e2439c48b98516a8047c1e801551c32edc1a1c8",
}

RASTERS = {
    "top_down_rgb": True,
    "occupancy_grid_map": True,
    "drivable_area_grid_map": True,
    "img_pixels": 32,
}


def canonical(value) -> object:
    """``value`` as nested tuples of plain strings: arrays by their dtype, shape, flags and
    bytes; dicts in key order; everything else by type and repr."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        digest = hashlib.sha256(value.tobytes()).hexdigest()
        return (
            "ndarray",
            value.dtype.str,
            value.shape,
            flags.writeable,
            flags.c_contiguous,
            digest,
        )
    if isinstance(value, dict):
        return ("dict", tuple((key, canonical(item)) for key, item in value.items()))
    if isinstance(value, list | tuple):
        return (type(value).__name__, tuple(canonical(item) for item in value))
    return (type(value).__name__, repr(value))


class Digest:
    def __init__(self) -> None:
        self._sha = hashlib.sha256()

    def add(self, *values) -> None:
        self._sha.update(repr(canonical(values)).encode())

    def hexdigest(self) -> str:
        return self._sha.hexdigest()


def lane_speeds(seed: int) -> Callable[[dict], np.ndarray]:
    """LaneWithContinuousSpeed: seeded speeds, now and then a lane change."""
    rng = np.random.default_rng(seed)

    def policy(obs: dict) -> np.ndarray:
        change = rng.choice([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
        return np.array([rng.uniform(0.0, 16.0), change], np.float32)

    return policy


def follow_gap(obs: dict) -> np.ndarray:
    """TargetPose along the ego's heading, slowing for the nearest neighbour ahead."""
    x, y, _ = obs["ego_vehicle_state"]["position"].tolist()
    heading = obs["ego_vehicle_state"]["heading"].item()
    nbr = obs["neighborhood_vehicle_states"]
    ahead = (nbr["mask"] > 0) & (
        np.hypot(nbr["position"][:, 0] - x, nbr["position"][:, 1] - y) < 30
    )
    speed = 6.0 if ahead.any() else 14.0
    d = speed * 0.1
    return np.array([x + d * np.cos(heading), y + d * np.sin(heading), heading, 0.1], np.float32)


def gym_episode(env: DrivingArenaEnv, policy, seed: int, steps: int) -> str:
    digest = Digest()
    try:
        obs, info = env.reset(seed=seed)
        digest.add(obs, info, env.render())
        for _ in range(steps):
            out = env.step(policy(obs))
            obs = out[0]
            digest.add(*out, env.render())
            if out[2] or out[3]:
                break
    finally:
        env.close()
    return digest.hexdigest()


def car_ahead(root: Path) -> Path:
    spec = ScenarioSpec(
        missions=(mission(start=(20.0, lane_y(1), 0.0), speed=10.0),),
        vehicles=[vehicle_xml("slow", 37.25, 1, 0.0, vtype="steady")],
    )
    return make_scenario(root / "ahead", spec)


def episode(name: str, tmp: Path) -> str:
    if name == "cruise_rasters":
        env = DrivingArenaEnv(
            PUBLIC / "p016_cruise_2lane_low",
            action_space="LaneWithContinuousSpeed",
            render_mode="rgb_array",
            **RASTERS,
        )
        return gym_episode(env, lane_speeds(3), seed=1, steps=120)
    if name == "cut_in_target_pose":
        env = DrivingArenaEnv(
            PUBLIC / "p021_cut_in_3lane_mid", action_space="TargetPose", traffic_seed="random"
        )
        return gym_episode(env, follow_gap, seed=5, steps=150)
    if name == "collision":
        env = DrivingArenaEnv(car_ahead(tmp), action_space="RelativeTargetPose")
        return gym_episode(env, lambda obs: np.array([2.8, 0.0, 0.0]), seed=0, steps=40)
    if name == "step_limit_child":
        folder = make_scenario(tmp / "short", ScenarioSpec(max_episode_steps=30))
        env = DrivingArenaEnv(folder, action_space="Continuous", simulator="subprocess")
        return gym_episode(env, lambda obs: np.array([0.3, 0.0, 0.1]), seed=0, steps=40)
    return parallel_episode()


def parallel_episode() -> str:
    env = DrivingArenaParallelEnv(
        PUBLIC / "p020_cruise_3lane_curve_low_3agents", action_space="LaneWithContinuousSpeed"
    )
    digest = Digest()
    policy = lane_speeds(11)
    try:
        digest.add(*env.reset(seed=0))
        for _ in range(1000):
            actions = {a: policy({}) for a in env.agents}
            digest.add(*env.step(actions), env.agents)
            if not env.agents:
                break
    finally:
        env.close()
    return digest.hexdigest()


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_environments_return_what_they_returned(name, tmp_path) -> None:
    assert episode(name, tmp_path) == EXPECTED[name]


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as root:
        for case in EXPECTED:
            folder = Path(root) / case
            folder.mkdir()
            print(f'    "{case}": "{episode(case, folder)}",')
