"""The reference planner's episode on a shipped public scenario, hashed three ways: every action
it answers (``tests/examples/test_planner_actions.py``), every observation it is given
(``tests/sim/test_record_regression.py``) and the episode's record (both)."""

from __future__ import annotations

import fcntl
import hashlib
import json
from pathlib import Path
from typing import NamedTuple

from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.experts import PlannerAgent, planner_interface
from sim.episode import run_episode
from sim.inputs import ScenarioInputs


class PlannerDigests(NamedTuple):
    """sha256 hex digests of one episode."""

    actions: str  # every step's actions as JSON (exact float reprs)
    observations: str  # every observation as JSON
    record: str  # the .npz record's bytes


class _HashedPlanner(PlannerAgent):
    """The reference planner, hashing every observation it is given and every action it answers."""

    def __init__(self) -> None:
        super().__init__()
        self.observations = hashlib.sha256()
        self.actions = hashlib.sha256()

    def act(self, obs):
        self.observations.update(json.dumps(obs, sort_keys=True).encode())
        actions = super().act(obs)
        as_floats = {k: [float(v) for v in action] for k, action in actions.items()}
        self.actions.update(json.dumps(as_floats, sort_keys=True).encode())
        return actions


def planner_digests(
    scenario_id: str, folder: Path, inputs: ScenarioInputs | None = None
) -> PlannerDigests:
    """Run the planner on ``scenario_id`` (its record written in ``folder``)."""
    agent = _HashedPlanner()
    record = folder / "record.npz"
    scenario_dir = SHIPPED_PUBLIC_DIR / scenario_id
    run_episode(scenario_dir, agent, planner_interface(), record_path=record, inputs=inputs)
    return PlannerDigests(
        agent.actions.hexdigest(),
        agent.observations.hexdigest(),
        hashlib.sha256(record.read_bytes()).hexdigest(),
    )


def planner_digests_once(scenario_id: str, shared: Path) -> PlannerDigests:
    """:func:`planner_digests`, run once for every process of a test session that shares the
    folder ``shared``: the first to ask runs the episode under a lock and keeps its digests there,
    the others wait for them and read them (a planner episode costs about a second of CPU)."""
    folder = shared / scenario_id
    folder.mkdir(parents=True, exist_ok=True)
    kept = folder / "digests.json"
    with open(folder / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not kept.exists():
            kept.write_text(json.dumps(planner_digests(scenario_id, folder)))
        return PlannerDigests(*json.loads(kept.read_text()))
