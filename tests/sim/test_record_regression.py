"""Records and observations of public scenarios must not change with simulator refactors.

Speed work (bulk SUMO reads, vectorised geometry, leaner observation building) must keep every
record byte and every observation value. The digests below were last taken when waypoint paths
began at the vehicle's own offset along its lane (level with it, as SMARTS documents; before,
at the next whole metre): every observation changed, and the records of the agents that follow
waypoints on the junction and curve (the planner on p000 and p020, keep-lane on p000); the
random agents' and the replays' records are unchanged. They were re-taken once more when the
simulator's arctangents, sines and cosines moved from numpy to the C library
(``arena/portable_math.py``): numpy's differ in the last bit on AVX-512 CPUs, so the digests of
the junction and curve scenarios depended on the machine. A deliberate change of records or
observations (new fields, other waypoints, other terminal steps) updates them in the same commit,
saying why:
``python -m tests.sim.test_record_regression`` prints the current digests.

The planner drives with the default observation; :data:`EXPECTED_INTERFACES` covers the other
action spaces and the optional parts (rasters, shorter waypoint paths, other radii) with the
keep-lane example and seeded random actions (lists, tuples and arrays), which also end episodes
off road and in collisions. Those digests were taken before the per-step speed work of the
simulator (bulk neighbour reads, lane shortcuts of the area tests, plain-float poses); those of
the smarts2022 format (keep-lane with road waypoints) before its waypoint dicts were made from
the arrays the arrays format is written from.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from arena.examples import example_dir
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.episode import run_episode
from sim.inputs import ScenarioInputs
from sim.interface import AgentInterface
from tests.planner_episodes import planner_digests

# scenario id -> (sha256 of the .npz record, sha256 of every observation the agent got as JSON)
EXPECTED = {
    # SUMO traffic through a junction, one agent
    "p000_left_turn_t_low": (
        "8078e1bbfd80d4f573b5db0ddcf438537040ba9bfb410118691105d3f225b8a3",
        "5173419b63973581b1f5fcff5f9388b7b42c6741fd346146f36eaa1175ae044b",
    ),
    # three agents sharing a curved road (neighbours include the other egos)
    "p020_cruise_3lane_curve_low_3agents": (
        "bc779e10bf0630e0c9092c39d80a83be69fb9f2dfb6e52be7da514ee43abb480",
        "875ec534bbb9fd360716a8a1219c6b17e426be4331986b4b35a5f37f7288d15c",
    ),
    # a scripted cut-in (triggers move SUMO vehicles)
    "p021_cut_in_3lane_mid": (
        "942c39d552eb9ed3dcfb16f4aa47ca7b7c1a85584437b6571b3bf361b272bd38",
        "89357323b1593f6dd11043b5a0b2602d15c406434e47e7d159417abd0e01c1a9",
    ),
    # replayed traffic inside a reactive bubble
    "p029_replay_i80_bubble": (
        "0fef460325a0bf42fd38f3240ae4b82f7e9eb5777424924886e85f1a817ecb04",
        "651ad2804d6ac39abbe611cb54c7b63273780e6b6e47d08b9b97494f4773b9a6",
    ),
    # replayed traffic outside SUMO
    "p030_replay_cruise": (
        "000fbcab4b433e6bb42938d8ae635d4190d46e6cad1804022d729398910369e3",
        "22c251855e5db5e518bf6aa5f301720268085028d3e551e8e44e90b9ce4d4d20",
    ),
}


# (scenario id, agent) -> (sha256 of the .npz record, sha256 of every observation as JSON, arrays
# as their dtype, shape and sha256)
EXPECTED_INTERFACES = {
    ("p000_left_turn_t_low", "keep_lane_rasters"): (
        "b2d474349584d1d9979db51da91de76a50aeabe142fdc0ffe55feb24f32c0c0a",
        "f203772388a7ca9849319dccca7315057b08137c0bfe6175fbd049b65e073294",
    ),
    ("p000_left_turn_t_low", "continuous_random"): (
        "e04754b7953ddbc0907a4ffdc1aa87595c78d38c1e32d688b61517d04a93ebb2",
        "f4230616b635c54fc1ec194994c2ea4221cf8c59e861d1e126c4866c13163f61",
    ),
    ("p000_left_turn_t_low", "relative_random"): (
        "8e7ca6d63549313283f5fa3eab839f9a96a9492390cdf9e6c0905220a692f180",
        "4316d9138e1e6dab058c27292eb6da3e0fb04c7c29826a03323d253061d50c3b",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "keep_lane_rasters"): (
        "ac35c4d87a3c891cdd134381d4afa257ac41b0ea847ee065a146c52e3fc1dad6",
        "e15160a6968739a43c944e8272a9b6c6e95801c6cf97164928d7c87050ee9665",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "continuous_random"): (
        "7028497f54113f5dce5f998dbc78a1db7b4f8600a6ab2ac62762baee4dd21ef3",
        "8a5d600fdf39246bd6a5671dfb58c56dfcfcdcc834b25b082b762b893e732555",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "relative_random"): (
        "f4dbe952db25dad23eeba2406c4dda0c317c1f926504fde819060fad4947d8fa",
        "40bc7fda6106c69d12c65f4a1f517b3e6610ef7a3b5c2e28c671a77d451607b7",
    ),
    ("p029_replay_i80_bubble", "keep_lane_rasters"): (
        "dca8f0bdc5b93230da7290815869d9645de26ef1ed6fcfb49851b18fee5c1d62",
        "2bd8dcec773faeadc2433a1077e4a6b027d8a8539522fe685c5f02fe61993287",
    ),
    ("p029_replay_i80_bubble", "continuous_random"): (
        "f44b9f92d40b86da0629e452fad19126c8cc23fc870309320a5ba970b4173d78",
        "2a457b62a3933e36a8fa7e2190f4a5edf6d24389806380bc4a8481cb34dba552",
    ),
    ("p029_replay_i80_bubble", "relative_random"): (
        "973c302620a60f01bd993c20a9f840798b401eac0bd672130d78bc144a95a7ad",
        "fffd9dfa31e56688dfdaf71b738ee6a6506efeeb37d28f160568307f42e86740",
    ),
    ("p030_replay_cruise", "keep_lane_rasters"): (
        "00adc231514de66a35730924261635d87962b3d5911b8c5f4d5289b49d9f7416",
        "fa2387190e3362d7001f029969e57b99e75a83c4cf0176429bde3d84a5116dc6",
    ),
    ("p030_replay_cruise", "continuous_random"): (
        "78e192e1eebfcfe847bedd4e9d6f284245df6d41c9b171bacd270606278b2a63",
        "9ba951582d47dbbee5f56943728fab472bde5320cc7f994f2118bc2c3ae0a971",
    ),
    ("p030_replay_cruise", "relative_random"): (
        "d3e22b03a7e03e9970ac9db049eca05b54eddc82de37a8cde58ca30b78dfe3d6",
        "0efb00889da8055212225a52f217bddd1ed443537f7363cbce9df0fdd133fa90",
    ),
    ("p000_left_turn_t_low", "keep_lane_smarts2022"): (
        "b2d474349584d1d9979db51da91de76a50aeabe142fdc0ffe55feb24f32c0c0a",
        "95fdab78a92ec94ed8f71a653a4f4726a6b451b7dffb0e367e8e75534ecf77cc",
    ),
    ("p020_cruise_3lane_curve_low_3agents", "keep_lane_smarts2022"): (
        "4a5b3148ca05d48c884f6fc395ceb6978f84aa976e8d3071fbd7d52e38311f92",
        "3e3213cbfd5fba8f141a59fdb7dc36707c014af113fc6c0fe7f03d551d933764",
    ),
    ("p029_replay_i80_bubble", "keep_lane_smarts2022"): (
        "918a523cda3135c555cf107847d0cba8682ae175768dba4a59c8b48d48786f70",
        "6558b14617058417dbd96ddf0d7cf76aff7ffbd01903b20d15c743aff2c76e50",
    ),
    ("p030_replay_cruise", "keep_lane_smarts2022"): (
        "ac8d0f1afd1cb798001dfe4e3c1720f725042a1941d7bbb60e191f6abde01058",
        "d9aa00123b5e06f9fb5199b609243c8673dd31176c3fd94176a903d060418919",
    ),
}

# junction, three agents, replay in a reactive bubble, replay outside SUMO
REGRESSION_SCENARIOS = (
    "p000_left_turn_t_low",
    "p020_cruise_3lane_curve_low_3agents",
    "p029_replay_i80_bubble",
    "p030_replay_cruise",
)
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
    # The smarts2022 format's dicts: one waypoint more per path, and the road waypoints.
    "keep_lane_smarts2022": AgentInterface(
        action_space="LaneWithContinuousSpeed", observation_format="smarts2022", road_waypoints=True
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
            "keep_lane_policy", example_dir("keep_lane") / "policy.py"
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
        _KeepLane()
        if name.startswith("keep_lane")
        else _SeededRandom(INTERFACES[name].action_space)
    )


def digests(
    scenario_id: str, folder: Path, inputs: ScenarioInputs | None = None
) -> tuple[str, str]:
    run = planner_digests(scenario_id, folder, inputs)
    return run.record, run.observations


def interface_digests(scenario_id: str, name: str, folder: Path) -> tuple[str, str]:
    agent = _Watched(_agent(name))
    record = folder / "record.npz"
    run_episode(SHIPPED_PUBLIC_DIR / scenario_id, agent, INTERFACES[name], record_path=record)
    return hashlib.sha256(record.read_bytes()).hexdigest(), agent.digest.hexdigest()


@pytest.mark.parametrize("scenario_id", sorted(EXPECTED))
def test_public_scenario_record_and_observations_unchanged(scenario_id, planner_episode):
    run = planner_episode(scenario_id)  # one run with tests/examples/test_planner_actions.py
    assert (run.record, run.observations) == EXPECTED[scenario_id]


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
