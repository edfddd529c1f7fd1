"""run_scenario and evaluate on small hand-made scenarios (tests/sim builders), process sandbox."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from arena.config import SandboxKind
from evaluator.runner import evaluate, run_scenario
from evaluator.summary import ScenarioStatus
from tests.runner.conftest import TEST_SANDBOX, write_policy

pytestmark = pytest.mark.slow

CRUISE = """
class Policy:
    def act(self, obs):
        return {agent_id: [10.0, 0] for agent_id in obs}
"""


@pytest.fixture
def submission(tmp_path):
    from submissions.intake import prepare_submission

    source = write_policy(tmp_path / "cruise", CRUISE)
    return prepare_submission(source, tmp_path / "prepared")


def scenario(folder: Path, *, broken: bool = False) -> Path:
    from tests.sim.builders import make_scenario

    make_scenario(folder)
    if broken:  # SUMO cannot load the map: a simulator error, not the agent's fault
        for net in folder.glob("*.net.xml"):
            net.write_text("<net><edge id=")
    return folder


def test_clean_episode_is_done_with_its_record(submission, tmp_path):
    outcome = run_scenario(
        submission, scenario(tmp_path / "ok"), tmp_path / "records", sandbox=TEST_SANDBOX
    )
    assert outcome.status == ScenarioStatus.done and outcome.attempts == 1
    assert [(a.id, a.reason) for a in outcome.agents] == [("Agent_0", "reached_goal")]
    assert outcome.record_path == tmp_path / "records" / "ok.npz"
    assert outcome.record_path.exists()


def test_simulator_error_is_retried_once_then_reported(submission, tmp_path):
    outcome = run_scenario(
        submission,
        scenario(tmp_path / "bad", broken=True),
        tmp_path / "records",
        sandbox=TEST_SANDBOX,
    )
    assert outcome.status == ScenarioStatus.simulator_error
    assert outcome.attempts == 2
    assert outcome.log.count("--- attempt") == 2
    assert outcome.record_path is None and not (tmp_path / "records" / "bad.npz").exists()
    assert outcome.error


def test_uncharged_scenario_leaves_n_and_is_listed(tmp_path):
    suite = tmp_path / "suite"
    scenario(suite / "ok")
    scenario(suite / "bad", broken=True)
    entries = [{"id": "ok", "family": "cruise"}, {"id": "bad", "family": "cruise"}]
    (suite / "manifest.json").write_text(json.dumps({"suite": "unit", "scenarios": entries}))

    summary = evaluate(
        write_policy(tmp_path / "cruise", CRUISE),
        suite,
        out_dir=tmp_path / "out",
        sandbox=TEST_SANDBOX,
    )

    assert summary.uncharged == ("bad",)
    assert summary.complete
    assert (summary.metrics.completion, summary.families["cruise"].completion) == (0.0, 0.0)
    assert summary.metrics.time == summary.scenarios[0].metrics.time  # N = 1


@pytest.mark.parametrize("kind", [None, *(k for k in SandboxKind if k is not SandboxKind.auto)])
def test_sandboxed_factory_preloads_only_modules_that_exist(submission, kind):
    import importlib.util

    from evaluator.runner.scenario import SandboxedAgentFactory

    modules = SandboxedAgentFactory(submission, kind, {}).preload_modules
    assert "evaluator.sandbox" in modules
    assert all(importlib.util.find_spec(m) is not None for m in modules)
    if kind is SandboxKind.docker:
        assert "docker" in modules
