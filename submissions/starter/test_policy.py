"""Run with `python -m pytest .` in this folder: the policy answers a realistic observation with
one valid action per agent, as the evaluator requires."""

import math
import os
import sys
from pathlib import Path

import yaml

from sim.interface import ACTION_LENGTH, AgentInterface
from submissions.sample import sample_observation

HERE = Path(__file__).resolve().parent


def load_policy():
    os.chdir(HERE)  # the evaluator runs the policy with its folder as working directory
    sys.path.insert(0, str(HERE))
    from policy import Policy

    return Policy()


def test_one_valid_action_per_agent():
    interface = AgentInterface(**(yaml.safe_load((HERE / "agent.yaml").read_text()) or {}))
    policy = load_policy()
    policy.reset()
    obs = sample_observation(("Agent_0", "Agent_1"))
    actions = policy.act(obs)
    assert isinstance(actions, dict)
    assert set(actions) == set(obs), "one action per agent id received"
    for action in actions.values():
        values = [float(v) for v in action]
        assert len(values) == ACTION_LENGTH[interface.action_space]
        assert all(math.isfinite(v) for v in values)
