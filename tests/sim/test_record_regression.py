"""Records and observations of public scenarios must not change with simulator refactors.

Speed work (bulk SUMO reads, vectorised geometry, leaner observation building) must keep every
record byte and every observation value. The digests below were taken with the per-vehicle
implementation before that work; a deliberate change of records or observations (new fields,
other waypoints, other terminal steps) updates them in the same commit, saying why:
``python -m tests.sim.test_record_regression`` prints the current digests.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
from pathlib import Path

import pytest

from scenarios.experts import PlannerAgent, planner_interface
from scenarios.suites import public_suite_dir
from sim.episode import run_episode

# scenario id -> (sha256 of the .npz record, sha256 of every observation the agent got as JSON)
EXPECTED = {
    # SUMO traffic through a junction, one agent
    "p000_left_turn_t_low": (
        "80ba2ca676b2af58794bfb3be99ae505fb269dccfc1cac2c9b441b14a34ca721",
        "b4e57db136be61bfb45bee205782bb13465f49fec2d322bc908cc11af1d1a9c3",
    ),
    # three agents sharing a curved road (neighbours include the other egos)
    "p020_cruise_3lane_curve_low_3agents": (
        "436fce3a01af4c15b1e44fd3189f393c15486c3781604b8d9467499129b94126",
        "d393018e4349306579515b162594f898192ac530d2190642eba270cf7c196e11",
    ),
    # a scripted cut-in (triggers move SUMO vehicles)
    "p021_cut_in_3lane_mid": (
        "01461a6bf668bdb914571d0aae26f4b06a0063a96e8841dd33921735ebb20617",
        "669032379c3368fff43acda82f6f6c7e6c7ad0624186377d9e6fe867440b08e8",
    ),
    # replayed traffic inside a reactive bubble
    "p029_replay_i80_bubble": (
        "0fef460325a0bf42fd38f3240ae4b82f7e9eb5777424924886e85f1a817ecb04",
        "396aca26c2aeff2f56a2ac5907cbb08cb8dfebe8cc8993ba0851b911a30065b3",
    ),
    # replayed traffic outside SUMO
    "p030_replay_cruise": (
        "000fbcab4b433e6bb42938d8ae635d4190d46e6cad1804022d729398910369e3",
        "32e33b269e101624a9b37ab57d9f02e1da3300b2cd38dfc31c751b0ff25801a2",
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


def digests(scenario_id: str, folder: Path) -> tuple[str, str]:
    agent = _WatchedPlanner()
    record = folder / "record.npz"
    run_episode(public_suite_dir() / scenario_id, agent, planner_interface(), record_path=record)
    return hashlib.sha256(record.read_bytes()).hexdigest(), agent.digest.hexdigest()


@pytest.mark.parametrize("scenario_id", sorted(EXPECTED))
def test_public_scenario_record_and_observations_unchanged(scenario_id, tmp_path):
    assert digests(scenario_id, tmp_path) == EXPECTED[scenario_id]


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        for sid in sorted(EXPECTED):
            print(sid, *digests(sid, Path(tmp)))
