"""The reference planner's actions must not change with its speed work.

Every pose of every step (as exact float reprs) and the episode record are hashed on public
scenarios that exercise its branches: a junction with stop line and yielding, an on-ramp merge of
two agents, overtaking on a curve, three agents sharing a road, and a replay in a reactive bubble.
The digests were taken with the planner as it was before it was made faster, and re-taken
when the planner's and the simulator's arctangents moved from numpy (whose kernels differ in the
last bit on AVX-512 CPUs) to the C library's; a deliberate change
of its driving updates them in the same commit, saying why:
``python -m tests.examples.test_planner_actions`` prints the current digests.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from tests.planner_episodes import planner_digests

# scenario id -> (sha256 of every step's actions as JSON, sha256 of the .npz record)
EXPECTED = {
    "p000_left_turn_t_low": (
        "29768ce43d89502f4a5f1bdde46222cd762b24dfed00743b71f8091e09ea6c55",
        "8078e1bbfd80d4f573b5db0ddcf438537040ba9bfb410118691105d3f225b8a3",
    ),
    "p012_merge_3lane_curve_mid_2agents": (
        "700f903110cfbc4b579769e0644170977ebf035a14d6edcce4a486d559d838c4",
        "ffd8baba3edbafc9867458b79bbc050ffd7f21a00075912f47ea3496127cc3bb",
    ),
    "p020_cruise_3lane_curve_low_3agents": (
        "aa20b2917014fd12e286c6aebd5251b1c7338952e87e0a59bf9a3ddeb750f554",
        "bc779e10bf0630e0c9092c39d80a83be69fb9f2dfb6e52be7da514ee43abb480",
    ),
    "p026_overtake_3lane_curve_slow_mid": (
        "5a39ca246871cb21d5d547315e46e4dd67cc90151eeae1fa09a90b6388a93104",
        "adcb5dc0a29fe4348a084e2a81948988ebab7fd9988f79a3982f09f471a5826a",
    ),
    "p029_replay_i80_bubble": (
        "d1f6a71074ad44d3e414dac7510b3543480e9916e701dd5510d89d9699727e1d",
        "0fef460325a0bf42fd38f3240ae4b82f7e9eb5777424924886e85f1a817ecb04",
    ),
}


def digests(scenario_id: str, folder: Path) -> tuple[str, str]:
    run = planner_digests(scenario_id, folder)
    return run.actions, run.record


@pytest.mark.parametrize("scenario_id", sorted(EXPECTED))
def test_planner_actions_and_record_unchanged(scenario_id, planner_episode):
    run = planner_episode(scenario_id)  # one run with tests/sim/test_record_regression.py
    assert (run.actions, run.record) == EXPECTED[scenario_id]


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        for sid in sorted(EXPECTED):
            print(f"    {sid!r}: {digests(sid, Path(tmp))!r},")
