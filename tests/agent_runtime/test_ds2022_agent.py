"""A submission written the way Driving SMARTS 2022 agents were (``ds2022_agent/``: ``smarts`` and
``gym`` imports, the kit's ``submitted_wrappers()`` with ``FormatObs`` / ``FormatAction`` and a
wrapper of its own reading SMARTS's observation by attribute, later SMARTS's key names
(``format_obs_keys: later``), ``numpy==1.23.5`` pinned and ``np.float`` used) runs unmodified
on public scenarios in each sandbox, on the numpy it pinned (issue 24), which the results
manifest names."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.agent_runtime.ported import SANDBOXES, run_ported

pytestmark = pytest.mark.slow

AGENT = Path(__file__).parent / "ds2022_agent"
# A turn, a two-agent merge and a cruise of the public set.
SCENARIOS = [
    "p002_turn_c_left_turn_c_low",
    "p010_merge_2lane_shoulder_mid_2agents",
    "p016_cruise_2lane_low",
]


@pytest.mark.parametrize("kind", SANDBOXES)
def test_a_ds2022_agent_runs_unmodified_on_the_numpy_it_pinned(kind, tmp_path):
    summary, logs = run_ported(AGENT, SCENARIOS, kind, tmp_path / "out")
    reasons = {(s.id, a.id): a.reason for s in summary.scenarios for a in s.agents}
    assert "ds2022 agent on numpy 1.23.5" in logs
    # The manifest names the numpy the agent ran with, not the evaluator's.
    (environment,) = summary.manifest.environments
    assert environment.agent_stack["numpy"] == "1.23.5" != environment.numpy
    assert environment.agent_stack["gym"] == "0.21.0+arena"  # the compat package's
    reached = [k for k, r in reasons.items() if r == "reached_goal"]
    assert len(reached) >= len(reasons) - 1, reasons
