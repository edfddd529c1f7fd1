"""A submission written the way Driving SMARTS 2022 agents were (``ds2022_agent/``: ``smarts`` and
``gym`` imports, the kit's ``submitted_wrappers()`` with ``FormatObs`` / ``FormatAction`` and a
wrapper of its own reading SMARTS's observation by attribute, ``numpy==1.23.5`` pinned and
``np.float`` used) runs unmodified on public scenarios in each sandbox, on the numpy it pinned
(issue 24)."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import SandboxKind, get_settings
from evaluator.runner import evaluate
from tests.settings import evaluate_args

pytestmark = pytest.mark.slow

AGENT = Path(__file__).parent / "ds2022_agent"
AGENT_FAILURES = {"agent_error", "invalid_action", "agent_exited", "step_timeout", "init_timeout"}
# A turn, a two-agent merge and a cruise of the public set.
SCENARIOS = [
    "p002_turn_c_left_turn_c_low",
    "p010_merge_2lane_shoulder_mid_2agents",
    "p016_cruise_2lane_low",
]


@pytest.fixture(scope="module")
def public_suite() -> Path:
    from arena.suite import SHIPPED_PUBLIC_DIR

    return SHIPPED_PUBLIC_DIR


@pytest.mark.parametrize(
    "kind",
    [
        pytest.param(SandboxKind.docker, marks=pytest.mark.docker, id="docker"),
        pytest.param(SandboxKind.bubblewrap, marks=pytest.mark.bwrap, id="bubblewrap"),
        # Unisolated, but on the same interpreter and libraries where the machine has them.
        pytest.param(SandboxKind.process, id="process"),
    ],
)
def test_a_ds2022_agent_runs_unmodified_on_the_numpy_it_pinned(kind, public_suite, tmp_path):
    out = tmp_path / "out"
    summary = evaluate(
        AGENT,
        public_suite,
        **evaluate_args(get_settings()),
        out_dir=out,
        scenario_ids=SCENARIOS,
        sandbox=kind,
    )
    reasons = {(s.id, a.id): a.reason for s in summary.scenarios for a in s.agents}
    logs = "\n".join(p.read_text(errors="replace") for p in (out / "logs").glob("*.txt"))
    assert summary.complete and summary.uncharged == (), logs[-3000:]
    assert not {k: r for k, r in reasons.items() if r in AGENT_FAILURES}, (reasons, logs[-3000:])
    assert "ds2022 agent on numpy 1.23.5" in logs
    # The manifest names the numpy the agent ran with, not the evaluator's.
    (environment,) = summary.manifest.environments
    assert environment.agent_stack["numpy"] == "1.23.5" != environment.numpy
    assert environment.agent_stack["gym"] == "0.21.0+arena"  # the compat package's
    reached = [k for k, r in reasons.items() if r == "reached_goal"]
    assert len(reached) >= len(reasons) - 1, reasons
