from pathlib import Path

import numpy as np
import pytest

from sim.episode import run_episode
from sim.interface import ActionSpace, AgentInterface
from tests.sim.agents import Policy, ScriptedAgent


class Run:
    def __init__(self, result, record, agent):
        self.result, self.record, self.agent = result, record, agent

    @property
    def outcome(self):
        return self.result.agents[0]


@pytest.fixture
def run():
    """Run a scenario folder in this process with one policy for every agent."""

    def go(
        folder: Path,
        policy: Policy,
        space: ActionSpace = ActionSpace.TargetPose,
        record: str = "record.npz",
        **kwargs,
    ) -> Run:
        agent = ScriptedAgent(policy)
        # Outside the scenario folder: its content hash goes into the record.
        path = folder.parent / f"{folder.name}-records" / record
        result = run_episode(
            folder, agent, AgentInterface(action_space=space), record_path=path, **kwargs
        )
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        return Run(result, arrays, agent)

    return go
