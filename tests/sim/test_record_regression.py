"""Records and observations of public scenarios must not change with simulator refactors.

Speed work (bulk SUMO reads, vectorised geometry, leaner observation building) must keep every
record byte and every observation value. The digests below were last taken when waypoint paths
began to follow the mission route and a finishing agent began to get its last observation
(``done``): the planner drives the junction and cut-in scenarios differently since; the replays'
records are unchanged. A deliberate change of records or observations (new fields,
other waypoints, other terminal steps) updates them in the same commit, saying why:
``python -m tests.sim.test_record_regression`` prints the current digests.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
from pathlib import Path

import pytest

from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.experts import PlannerAgent, planner_interface
from sim.episode import run_episode
from sim.inputs import ScenarioInputs

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


@pytest.mark.parametrize("scenario_id", sorted(EXPECTED))
def test_public_scenario_record_and_observations_unchanged(scenario_id, tmp_path):
    assert digests(scenario_id, tmp_path) == EXPECTED[scenario_id]


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        for sid in sorted(EXPECTED):
            print(sid, *digests(sid, Path(tmp)))
