"""One rule for an agent among several that raises: the whole submission fails the episode, every
agent of it still driving ends with ``agent_error`` and that exception's traceback, on both
interfaces (a native policy, and a ``smarts2022`` one served through ``submitted_wrappers()``), as
SMARTS 2022's evaluation did (issue 41; ``docs/protocol.md``, "An exception in act")."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from arena.config import SandboxKind, get_settings
from evaluator.runner import EvaluationRequest, evaluate
from tests.settings import evaluate_args

pytestmark = pytest.mark.slow

SCENARIO = "p020_cruise_3lane_curve_low_3agents"
NATIVE = """
    class Policy:
        def act(self, obs):
            out = {}
            for agent_id, o in obs.items():
                if agent_id == "Agent_1":
                    raise ValueError("cannot drive " + agent_id)
                x, y = o["ego_vehicle_state"]["position"][:2]
                out[agent_id] = [x, y, o["ego_vehicle_state"]["heading"], 0.1]
            return out
"""
WRAPPED = """
    def submitted_wrappers():
        from smarts.env.wrappers.format_obs import FormatObs

        return [FormatObs]


    class Policy:
        def act(self, obs):
            out = {}
            for agent_id, o in obs.items():
                if agent_id == "Agent_1":
                    raise ValueError("cannot drive " + agent_id)
                x, y = o["ego"]["pos"][:2]
                out[agent_id] = [float(x), float(y), float(o["ego"]["heading"]), 0.1]
            return out
"""


@pytest.mark.parametrize(
    ("source", "agent_yaml"),
    [
        pytest.param(NATIVE, "action_space: TargetPose\n", id="native"),
        pytest.param(WRAPPED, "observation_format: smarts2022\n", id="smarts2022-wrappers"),
    ],
)
def test_one_agents_exception_ends_every_agent_of_the_episode(source, agent_yaml, tmp_path):
    from arena.suite import SHIPPED_PUBLIC_DIR

    folder = tmp_path / "agent"
    folder.mkdir()
    (folder / "policy.py").write_text(textwrap.dedent(source))
    (folder / "agent.yaml").write_text(agent_yaml)
    out = tmp_path / "out"
    summary = evaluate(
        EvaluationRequest(
            folder,
            SHIPPED_PUBLIC_DIR,
            out_dir=out,
            scenario_ids=[SCENARIO],
            sandbox=SandboxKind.process,
        ),
        **evaluate_args(get_settings()),
    )
    (scenario,) = summary.scenarios
    logs = "\n".join(p.read_text(errors="replace") for p in Path(out / "logs").glob("*.txt"))
    assert [a.id for a in scenario.agents] == ["Agent_0", "Agent_1", "Agent_2"]
    assert {a.reason.value for a in scenario.agents} == {"agent_error"}, logs[-2000:]
    assert "ValueError: cannot drive Agent_1" in logs
