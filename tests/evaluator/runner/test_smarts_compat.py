"""An agent written against the Driving SMARTS 2022 interface (``observation_format:
smarts2022``) drives public scenarios in the Docker sandbox (issue 10).

The example ``smarts_follower`` reads everything by attribute, checks SMARTS's heading frame on
its own motion and the per-step ``distance_travelled``, and raises when either is wrong; it
steers with TargetPose headings it computes in SMARTS's frame. A conversion error in either
direction therefore shows as ``agent_error`` or as vehicles leaving the road at once.
"""

from __future__ import annotations

import pytest

from arena.config import SandboxKind, get_settings
from arena.examples import example_dir
from evaluator.runner import EvaluationRequest, evaluate
from tests.settings import evaluate_args

pytestmark = pytest.mark.slow

AGENT_FAILURES = {"agent_error", "invalid_action", "agent_exited", "step_timeout", "init_timeout"}
# Scenarios of each SUMO-traffic family of the public set (turns, merges, cruising, cut-ins,
# overtaking), multi-agent ones included; the follower reaches every goal here.
SCENARIOS = [
    "p002_turn_c_left_turn_c_low",
    "p004_turn_c_left_turn_middle_lane_c_low",
    "p010_merge_2lane_shoulder_mid_2agents",
    "p016_cruise_2lane_low",
    "p019_cruise_2lane_low_2agents",
    "p021_cut_in_3lane_mid",
    "p023_overtake_2lane_low",
]


@pytest.mark.docker
def test_smarts_interface_agent_drives_public_scenarios_in_docker(public_suite, tmp_path):
    summary = evaluate(
        EvaluationRequest(
            example_dir("smarts_follower"),
            public_suite,
            out_dir=tmp_path / "out",
            scenario_ids=SCENARIOS,
            jobs=2,
            sandbox=SandboxKind.docker,
        ),
        **evaluate_args(get_settings()),
    )
    assert summary.complete and summary.uncharged == ()
    reasons = {(s.id, a.id): a.reason for s in summary.scenarios for a in s.agents}
    assert not {k: r for k, r in reasons.items() if r in AGENT_FAILURES}, reasons
    reached = [k for k, r in reasons.items() if r == "reached_goal"]
    # The follower reaches every one of these goals in the process sandbox; traffic may
    # differ in nothing (same seeds), so all of them must be reached here too.
    assert len(reached) == len(reasons), reasons
