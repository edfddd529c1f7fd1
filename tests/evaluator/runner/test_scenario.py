"""run_scenario and evaluate on small hand-made scenarios (tests/sim builders), process sandbox."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from arena.config import SandboxKind, get_settings
from arena.outcome import ScenarioStatus
from evaluator.runner import EvaluationRequest, evaluate, run_scenario
from tests.evaluator.runner.conftest import TEST_SANDBOX, write_policy
from tests.settings import evaluate_args, sandbox_args

pytestmark = pytest.mark.slow

CRUISE = """
class Policy:
    def act(self, obs):
        return {agent_id: [10.0, 0] for agent_id in obs}
"""


def prepared(source: Path, dest: Path):
    """The submission prepared as the service's settings say (the intake runs on this host)."""
    from submissions.intake import prepare_submission

    settings = get_settings()
    return prepare_submission(
        source, dest, settings.intake, settings.sandbox, settings.storage.resolved_data_dir
    )


@pytest.fixture
def submission(tmp_path):
    source = write_policy(tmp_path / "cruise", CRUISE)
    return prepared(source, tmp_path / "prepared")


def scenario(folder: Path, *, broken: bool = False) -> Path:
    from tests.sim.builders import make_scenario

    make_scenario(folder)
    if broken:  # SUMO cannot load the map: a simulator error, not the agent's fault
        for net in folder.glob("*.net.xml"):
            net.write_text("<net><edge id=")
    return folder


def test_clean_episode_is_done_with_its_record(submission, tmp_path):
    outcome = run_scenario(
        submission,
        scenario(tmp_path / "ok"),
        tmp_path / "records",
        **sandbox_args(get_settings()),
        sandbox=TEST_SANDBOX,
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
        **sandbox_args(get_settings()),
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
        EvaluationRequest(
            write_policy(tmp_path / "cruise", CRUISE),
            suite,
            out_dir=tmp_path / "out",
            sandbox=TEST_SANDBOX,
        ),
        **evaluate_args(get_settings()),
    )

    assert summary.uncharged == ("bad",)
    assert summary.complete
    assert (summary.metrics.completion, summary.families["cruise"].completion) == (0.0, 0.0)
    assert summary.metrics.time == summary.scenarios[0].metrics.time  # N = 1


@pytest.mark.parametrize(
    ("action", "rule"),
    [
        ("[1.7e308, 1.7e308, 0.0, 0.1]", "range"),  # was a NaN pose: simulator_error, uncharged
        ("[10**400, 0.0, 0.0, 0.1]", "not-numbers"),  # was an uncaught OverflowError
    ],
)
def test_an_agent_cannot_choose_an_uncharged_simulator_error(tmp_path, action, rule):
    """Bailing out through a value that broke the simulator left the scenario out of N: a
    planner doing so after 240 steps ranked first. Now it is the agent's invalid_action."""
    body = f"""
class Policy:
    def __init__(self):
        self.steps = 0

    def act(self, obs):
        self.steps += 1
        out = {{}}
        for agent_id, o in obs.items():
            x, y, _ = o["ego_vehicle_state"]["position"]
            h = o["ego_vehicle_state"]["heading"]
            out[agent_id] = {action} if self.steps > 3 else [x + 1.0, y, h, 0.1]
        return out
"""
    source = write_policy(tmp_path / "bail", body, action_space="TargetPose")
    submission = prepared(source, tmp_path / "prepared")
    outcome = run_scenario(
        submission,
        scenario(tmp_path / "ok"),
        tmp_path / "records",
        **sandbox_args(get_settings()),
        sandbox=TEST_SANDBOX,
    )
    assert outcome.status == ScenarioStatus.done and outcome.attempts == 1
    assert [(a.reason, a.steps) for a in outcome.agents] == [("invalid_action", 3)]
    assert f"[rule: {rule}]" in outcome.log


@pytest.mark.parametrize("kind", [None, *(k for k in SandboxKind if k is not SandboxKind.auto)])
def test_sandboxed_factory_preloads_only_modules_that_exist(submission, kind):
    import importlib.util

    from evaluator.runner.scenario import SandboxedAgentFactory

    settings = get_settings()
    factory = SandboxedAgentFactory(submission, kind, {}, **sandbox_args(settings))
    modules = factory.preload_modules
    assert "evaluator.sandbox" in modules
    assert all(importlib.util.find_spec(m) is not None for m in modules)
    if kind is SandboxKind.docker:
        assert "docker" in modules


def test_a_sandbox_lost_before_the_runner_started_is_retried_then_not_charged(submission, tmp_path):
    """Too little memory for the interpreter to start: the sandbox ends before our runner says
    hello, which no agent can cause (it runs none of the participant's code until then). In a
    fresh interpreter, so that the episode's simulator process reads the setting too."""
    import os
    import subprocess
    import sys

    folder = scenario(tmp_path / "ok")
    script = (
        "import json, sys\n"
        "from pathlib import Path\n"
        "from arena.config import get_settings\n"
        "from evaluator.runner import run_scenario\n"
        "from submissions.intake import prepare_submission\n"
        "from tests.settings import sandbox_args\n"
        f"source = Path({str(tmp_path / 'cruise')!r})\n"
        "settings = get_settings()\n"
        "group = settings.intake, settings.sandbox, settings.storage.resolved_data_dir\n"
        "s = prepare_submission(source, Path(sys.argv[1]), *group)\n"
        f"kind = {TEST_SANDBOX.value!r}\n"
        f"o = run_scenario(s, Path({str(folder)!r}), Path(sys.argv[2]), sandbox=kind,\n"
        "                 **sandbox_args(settings))\n"
        "print(json.dumps([o.status, o.attempts, o.error, o.log, str(o.record_path)]))\n"
    )
    env = {**os.environ, "ARENA_AGENT_MEMORY_BYTES": str(16 * 1024**2)}
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "again"), str(tmp_path / "records")],
        capture_output=True, text=True, env=env, cwd=Path(__file__).parents[3], timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    status, attempts, error, log, record = json.loads(done.stdout.splitlines()[-1])
    assert status == ScenarioStatus.evaluator_error, log
    assert attempts == 2 and log.count("--- attempt") == 2
    assert "sandbox_error" in log and "before the runner started" in error
    assert record == "None"
