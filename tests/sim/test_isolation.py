"""Episodes in a child process: results come back, crashes become simulator_error."""

import os
import subprocess
import sys
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from arena.outcome import DoneReason
from sim.episode import run_episode
from sim.interface import AgentInterface
from sim.isolation import preload_modules, run_episode_isolated
from tests.sim.agents import (
    PreloadProbe,
    ScriptedAgent,
    agent_that_times_out_at_init,
    crashing_agent,
    cruising_agent,
    hanging_agent,
    slow_agent,
    stand_still,
)
from tests.sim.builders import ScenarioSpec, make_scenario


@pytest.mark.slow
def test_isolated_episode_returns_the_result_and_agent_log(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    record = tmp_path / "out" / "sc.npz"
    result = run_episode_isolated(folder, cruising_agent, AgentInterface(), record_path=record)
    assert result.simulator_error is None
    assert result.agents[0].reason is DoneReason.reached_goal
    assert result.extra["agent_log"] == f"acted {result.steps} times"
    with np.load(record) as data:
        assert int(data["steps"][0]) == result.agents[0].steps


def test_picklable_partial_factory(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec(max_episode_steps=20))
    result = run_episode_isolated(
        folder,
        partial(ScriptedAgent, stand_still),
        AgentInterface(),
        record_path=tmp_path / "r.npz",
    )
    assert result.agents[0].reason is DoneReason.max_episode_steps and result.steps == 20


def test_a_crashing_process_yields_simulator_error(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    result = run_episode_isolated(
        folder, crashing_agent, AgentInterface(), record_path=tmp_path / "r.npz"
    )
    assert result.simulator_error and "exit code -11" in result.simulator_error
    assert [a.reason for a in result.agents] == [DoneReason.simulator_error]
    assert result.record_path is None


def test_sumo_failing_on_corrupt_input_yields_simulator_error(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    (folder / "traffic.rou.xml").write_text("<routes><vehicle id='x' route='nowhere'/></routes>")
    result = run_episode_isolated(
        folder, cruising_agent, AgentInterface(), record_path=tmp_path / "r.npz"
    )
    assert result.simulator_error and "SumoError" in result.simulator_error
    assert [a.reason for a in result.agents] == [DoneReason.simulator_error]
    assert "Traceback" in result.detail


def test_agent_failing_at_init_fails_every_agent_and_still_writes_the_record(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    record = tmp_path / "r.npz"
    result = run_episode_isolated(
        folder, agent_that_times_out_at_init, AgentInterface(), record_path=record
    )
    assert result.simulator_error is None
    assert [(a.reason, a.steps) for a in result.agents] == [(DoneReason.init_timeout, 0)]
    with np.load(record) as data:
        assert list(data["done_reason"]) == ["init_timeout"]
        assert data["x"].shape == (1, 0)


@pytest.mark.slow
def test_a_hung_episode_is_killed_at_the_hard_timeout(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    result = run_episode_isolated(
        folder, hanging_agent, AgentInterface(), record_path=tmp_path / "r.npz", timeout_s=3
    )
    assert result.simulator_error and "exceeded 3 s" in result.simulator_error
    assert [a.reason for a in result.agents] == [DoneReason.simulator_error]


@pytest.mark.slow
def test_wall_time_limit_ends_the_episode_keeping_the_record(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    record = tmp_path / "r.npz"
    result = run_episode(
        folder, slow_agent(), AgentInterface(), record_path=record, wall_timeout_s=0.5
    )
    assert [a.reason for a in result.agents] == [DoneReason.episode_timeout]
    assert 0 < result.agents[0].steps < 20
    with np.load(record) as data:
        assert int(data["steps"][0]) == result.agents[0].steps


def test_preload_names_the_simulator_the_factory_module_and_what_it_lists():
    modules = preload_modules(PreloadProbe())
    assert {"sim.simulation", "libsumo", "tests.sim.agents", "wave"} <= set(modules)
    assert len(modules) == len(set(modules))
    assert modules[-1] == "sim.forked"  # freezes what the others made


@pytest.mark.slow
def test_episode_children_start_with_the_factory_modules_already_imported(tmp_path):
    """A fresh process (its own fork server): every episode child has the listed module before
    the factory runs, because the server imported it once."""
    folder = make_scenario(tmp_path / "sc", ScenarioSpec(max_episode_steps=5))
    script = f"""
from pathlib import Path
from sim.interface import AgentInterface
from sim.isolation import run_episode_isolated
from tests.sim.agents import PreloadProbe

for i in range(2):
    result = run_episode_isolated(
        Path({str(folder)!r}), PreloadProbe(), AgentInterface(),
        record_path=Path({str(tmp_path)!r}) / f"{{i}}.npz",
    )
    print(result.simulator_error or result.extra["agent_log"])
"""
    repo = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=repo, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["preloaded=True", "frozen=True"] * 2


@pytest.mark.slow
def test_episode_children_do_not_run_the_main_script_again(tmp_path):
    """multiprocessing would run the main script again in every episode's child (for ``arena
    evaluate``, importing every command's modules): the factory does not come from it."""
    folder = make_scenario(tmp_path / "sc", ScenarioSpec(max_episode_steps=5))
    runs = tmp_path / "main-runs.txt"
    script = tmp_path / "main_script.py"
    script.write_text(
        f"""
from pathlib import Path

with open({str(runs)!r}, "a") as runs:
    runs.write(__name__ + "\\n")

if __name__ == "__main__":
    from sim.interface import AgentInterface
    from sim.isolation import run_episode_isolated
    from tests.sim.agents import PreloadProbe

    for i in range(3):
        result = run_episode_isolated(
            Path({str(folder)!r}), PreloadProbe(), AgentInterface(),
            record_path=Path({str(tmp_path)!r}) / f"{{i}}.npz",
        )
        assert result.simulator_error is None, result.simulator_error
"""
    )
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(repo)}
    done = subprocess.run(
        [sys.executable, str(script)], cwd=repo, env=env, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert runs.read_text().split() == ["__main__"]
