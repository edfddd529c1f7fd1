"""Every shipped public scenario loads and simulates 50 steps (each in its own process)."""

from __future__ import annotations

import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from arena.suite import SHIPPED_PUBLIC_DIR
from tests.scenarios.conftest import manifest


def run_50_steps(folder: Path) -> tuple[str, int, int]:
    from arena.scenario import load_scenario
    from sim.interface import ActionSpace, AgentInterface
    from sim.simulation import Simulation

    scenario = load_scenario(folder)
    interface = AgentInterface(action_space=ActionSpace.LaneWithContinuousSpeed)
    sim = Simulation(scenario, folder, interface)
    seen = 0
    try:
        obs = sim.reset()
        for _ in range(50):
            obs = sim.step({agent_id: [8.0, 0.0] for agent_id in obs})
            seen = max(seen, len(sim.background_states()))
    finally:
        sim.close()
    return scenario.id, sim.step_count, seen


@pytest.mark.slow
def test_every_public_scenario_runs_50_steps():
    folder = SHIPPED_PUBLIC_DIR
    entries = manifest(folder)["scenarios"]
    ids = [e["id"] for e in entries]
    # Low-volume intersections may see their first arrival after 5 s; every other scenario has
    # traffic around from the start.
    quiet_allowed = {
        e["id"]
        for e in entries
        if e["family"] in ("left_turn_t", "turn_c") and e["volume"] == "low"
    }
    ctx = mp.get_context("forkserver")
    with ProcessPoolExecutor(max_workers=2, mp_context=ctx, max_tasks_per_child=1) as pool:
        results = list(pool.map(run_50_steps, [folder / i for i in ids]))
    assert [r[0] for r in results] == ids
    for sid, steps, seen in results:
        assert steps == 50, sid
        assert seen > 0 or sid in quiet_allowed, f"{sid}: no background traffic"
