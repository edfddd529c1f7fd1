"""Records and observations of public scenarios must not change with simulator refactors.

Speed work (bulk SUMO reads, vectorised geometry, leaner observation building) must keep every
record byte and every observation value. The digests below were last taken when waypoint paths
began to follow the mission route and a finishing agent began to get its last observation
(``done``): the planner drives the junction and cut-in scenarios differently since; the replays'
records are unchanged. A deliberate change of records or observations (new fields,
other waypoints, other terminal steps) updates them in the same commit, saying why:
``python -m tests.sim.test_record_regression`` prints the current digests.

The planner drives with the default observation; :data:`EXPECTED_INTERFACES` covers the other
action spaces and the optional parts (rasters, shorter waypoint paths, other radii) with the
keep-lane example and seeded random actions (lists, tuples and arrays), which also end episodes
off road and in collisions. Those digests were taken before the per-step speed work of the
simulator (bulk neighbour reads, lane shortcuts of the area tests, plain-float poses).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.experts import PlannerAgent, planner_interface
from sim.episode import run_episode
from sim.inputs import ScenarioInputs
from sim.interface import AgentInterface

# scenario id -> (sha256 of the .npz record, sha256 of every observation the agent got as JSON)
EXPECTED = {
    # SUMO traffic through a junction, one agent
    "p000_left_turn_t_low": (
        "5b46ed7e93352bd05a6b70f76f55fb2c091c4c2da6bc0c0d23edf5fa5775c8a9",
        "29b65e108a5269a9d1ae71d6dfde29bd3815410784ea6e3984ad4775c30d7a23",
    ),
    # three agents sharing a curved road (neighbours include the other egos)
    "p020_cruise_3lane_curve_low_3agents": (
        "e77b56709005dbce8860f06daf06c721c6cc470b8b01829f31111a85924621ed",
        "c7bf2590138286ce2302d85fc19d7918d60720e068af38cdc38028169f81a5c6",
    ),
    # a scripted cut-in (triggers move SUMO vehicles)
    "p021_cut_in_3lane_mid": (
        "942c39d552eb9ed3dcfb16f4aa47ca7b7c1a85584437b6571b3bf361b272bd38",
        "afd809104da35219a32974df9e8f5b1d895890e646f67cee31e94be012fbb722",
    ),
    # replayed traffic inside a reactive bubble
    "p029_replay_i80_bubble": (
        "0fef460325a0bf42fd38f3240ae4b82f7e9eb5777424924886e85f1a817ecb04",
        "2aa86be6a3c52149749fd31d3d5583ffbe99bd71fe2205a16048e90995697eef",
    ),
    # replayed traffic outside SUMO
    "p030_replay_cruise": (
        "000fbcab4b433e6bb42938d8ae635d4190d46e6cad1804022d729398910369e3",
        "5524eeb164dc1f3ae09f85126293ff3eeb2519ba41e453831b345a7f15e19a4f",
    ),
}


# (scenario id, agent) -> (sha256 of the .npz record, sha256 of every observation as JSON, arrays
# as their dtype, shape and sha256)
EXPECTED_INTERFACES = {
    ("p000_left_turn_t_low", "keep_lane_rasters"): (
        "b1fccc80af54eb397a6da2480d542118c17decced3f9133c597c11ccce7df46e",
        "825e9356056ae96077cdf4708c32368c05d82520871187a85501c545515a2bc3",
    ),
    ("p000_left_turn_t_low", "continuous_random"): (
        "e04754b7953ddbc0907a4ffdc1aa87595c78d38c1e32d688b61517d04a93ebb2",
        "e4ff3a5d8f022dee1d44dc71ee83c4cd012b57cdedf48e8e7ee4c239cbba00ce",
    ),
    ("p000_left_turn_t_low", "relative_random"): (
        "8e7ca6d63549313283f5fa3eab839f9a96a9492390cdf9e6c0905220a692f180",
        "c1ba605ab3152c71ec5333573883e8ff0a5cef1a805787e47db8699574900735",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "keep_lane_rasters"): (
        "ad398df72e88d8d14a07194c3b416550a3ed2385e97e2a56fa8f3366ae67b0f5",
        "807baa8fd5d59d15f6a705e24aaaafd6c707ac73099e8ff41b72336f843f2c13",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "continuous_random"): (
        "7028497f54113f5dce5f998dbc78a1db7b4f8600a6ab2ac62762baee4dd21ef3",
        "f049378f2d5a1905aaf1442f276345d8e7bd340cd7e1a82627751a0921519c51",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "relative_random"): (
        "ddd1b0c97ba347fc232eb2d13ca89b4b1a94f3544e40ca614854519f91e7eaf4",
        "37e930c5eed010e1140b0c91c370a8878cd91d271571ef35466921ba51519c27",
    ),
    ("p029_replay_i80_bubble", "keep_lane_rasters"): (
        "dca8f0bdc5b93230da7290815869d9645de26ef1ed6fcfb49851b18fee5c1d62",
        "eaee2e3e949169946906e6cf70f14fccb70a529ecd7e1897454f6e0189a32e85",
    ),
    ("p029_replay_i80_bubble", "continuous_random"): (
        "f44b9f92d40b86da0629e452fad19126c8cc23fc870309320a5ba970b4173d78",
        "05361d515ba16d5835e37bf8bdffab6c1be32b4d4ee0de061ba862042854617a",
    ),
    ("p029_replay_i80_bubble", "relative_random"): (
        "973c302620a60f01bd993c20a9f840798b401eac0bd672130d78bc144a95a7ad",
        "d387fc0fcedf7f3d2cf48501662a43f87170b2a607827794b2ad6f42fea493ba",
    ),
    ("p030_replay_cruise", "keep_lane_rasters"): (
        "00adc231514de66a35730924261635d87962b3d5911b8c5f4d5289b49d9f7416",
        "8a0ecc5053976abce4cd1c83e49a8923f653f8196aaa49dfbc17982cc5255a03",
    ),
    ("p030_replay_cruise", "continuous_random"): (
        "78e192e1eebfcfe847bedd4e9d6f284245df6d41c9b171bacd270606278b2a63",
        "99b41bac16cbefdb509d9c4ff6c240e1cb727398c87fb8d76bd9fce6fa231d96",
    ),
    ("p030_replay_cruise", "relative_random"): (
        "d3e22b03a7e03e9970ac9db049eca05b54eddc82de37a8cde58ca30b78dfe3d6",
        "85dc9ed697685d21eeb200c5300405113b60bd60b7176345761cb09dbd9b4094",
    ),
}

# junction, three agents, replay in a reactive bubble, replay outside SUMO
REGRESSION_SCENARIOS = (
    "p000_left_turn_t_low",
    "p020_cruise_3lane_curve_low_3agents",
    "p029_replay_i80_bubble",
    "p030_replay_cruise",
)
KEEP_LANE_DIR = Path(__file__).resolve().parents[2] / "submissions" / "examples" / "keep_lane"
INTERFACES = {
    "keep_lane_rasters": AgentInterface(
        action_space="LaneWithContinuousSpeed",
        top_down_rgb=True,
        occupancy_grid_map=True,
        drivable_area_grid_map=True,
        img_pixels=48,
        max_waypoint_paths=3,
        waypoints_per_path=20,
        observation_radius=60.0,
    ),
    "continuous_random": AgentInterface(action_space="Continuous", observation_radius=150.0),
    "relative_random": AgentInterface(action_space="RelativeTargetPose"),
}


class _Watched:
    """Hashes every observation ``inner`` is given (arrays by dtype, shape and bytes)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.digest = hashlib.sha256()

    def reset(self) -> None:
        self.inner.reset()

    def act(self, obs):
        self.digest.update(json.dumps(obs, sort_keys=True, default=_array_digest).encode())
        return self.inner.act(obs)


def _array_digest(value) -> list:
    array = np.asarray(value)
    return [str(array.dtype), list(array.shape), hashlib.sha256(array.tobytes()).hexdigest()]


class _KeepLane:
    def reset(self) -> None:
        spec = importlib.util.spec_from_file_location(
            "keep_lane_policy", KEEP_LANE_DIR / "policy.py"
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        self.policy = module.Policy()

    def act(self, obs):
        return self.policy.act(obs)


class _SeededRandom:
    """Continuous: lists and arrays of random throttle and steering; RelativeTargetPose: tuples
    of random small displacements. The same actions every run."""

    def __init__(self, space: str) -> None:
        self.space = space

    def reset(self) -> None:
        self.rng = np.random.default_rng(3)
        self.steps = 0

    def act(self, obs):
        self.steps += 1
        out = {}
        for agent_id in sorted(obs):
            u = self.rng.uniform(size=3).tolist()
            if self.space == "Continuous":
                action = [0.2 + 0.6 * u[0], 0.0, 1.2 * u[1] - 0.6]
                out[agent_id] = action if self.steps % 2 else np.array(action)
            else:
                out[agent_id] = (1.2 + u[0], 0.2 * u[1] - 0.1, 0.1 * u[2] - 0.05)
        return out


def _agent(name: str):
    return (
        _KeepLane() if name == "keep_lane_rasters" else _SeededRandom(INTERFACES[name].action_space)
    )


class _WatchedPlanner(PlannerAgent):
    """The reference planner, hashing every observation it is given."""

    def __init__(self) -> None:
        super().__init__()
        self.digest = hashlib.sha256()

    def act(self, obs):
        self.digest.update(json.dumps(obs, sort_keys=True).encode())
        return super().act(obs)


def digests(
    scenario_id: str, folder: Path, inputs: ScenarioInputs | None = None
) -> tuple[str, str]:
    agent = _WatchedPlanner()
    record = folder / "record.npz"
    scenario_dir = SHIPPED_PUBLIC_DIR / scenario_id
    run_episode(scenario_dir, agent, planner_interface(), record_path=record, inputs=inputs)
    return hashlib.sha256(record.read_bytes()).hexdigest(), agent.digest.hexdigest()


def interface_digests(scenario_id: str, name: str, folder: Path) -> tuple[str, str]:
    agent = _Watched(_agent(name))
    record = folder / "record.npz"
    run_episode(SHIPPED_PUBLIC_DIR / scenario_id, agent, INTERFACES[name], record_path=record)
    return hashlib.sha256(record.read_bytes()).hexdigest(), agent.digest.hexdigest()


@pytest.mark.parametrize("scenario_id", sorted(EXPECTED))
def test_public_scenario_record_and_observations_unchanged(scenario_id, tmp_path):
    assert digests(scenario_id, tmp_path) == EXPECTED[scenario_id]


@pytest.mark.parametrize(("scenario_id", "name"), sorted(EXPECTED_INTERFACES))
def test_other_interfaces_records_and_observations_unchanged(scenario_id, name, tmp_path):
    assert interface_digests(scenario_id, name, tmp_path) == EXPECTED_INTERFACES[scenario_id, name]


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        for sid in sorted(EXPECTED):
            print(sid, *digests(sid, Path(tmp)))
        for sid in REGRESSION_SCENARIOS:
            for name in INTERFACES:
                print(f"    ({sid!r}, {name!r}): {interface_digests(sid, name, Path(tmp))!r},")
