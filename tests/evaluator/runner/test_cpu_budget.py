"""The evaluation's CPU budget in `arena evaluate`: real simulator, real sandboxed agents whose
acts burn CPU. Past the budget no more episodes start; `agent_cpu.json` keeps the total, so a
resumed run keeps counting; --force starts over."""

from __future__ import annotations

import json

import pytest

from arena.config import get_settings
from arena.cpu_limits import CpuLimits
from evaluator.runner import EvaluationRequest, evaluate
from evaluator.runner.cpu_budget import AGENT_CPU_FILE, read_agent_cpu
from tests.evaluator.runner.conftest import TEST_SANDBOX, write_policy
from tests.evaluator.runner.test_evaluate import few_scenarios
from tests.settings import evaluate_args

pytestmark = [pytest.mark.slow, pytest.mark.integration]

# Lane keeping at 8 m/s; each of the first BUSY_ACTS acts first burns BURN_S of its own CPU.
BUSY_POLICY = """
import time

BUSY_ACTS = 10
BURN_S = 0.03


class Policy:
    def __init__(self):
        self.acts = 0

    def act(self, obs):
        self.acts += 1
        if self.acts <= BUSY_ACTS:
            start = time.process_time()
            while time.process_time() - start < BURN_S:
                pass
        return {agent_id: [8.0, 0] for agent_id in obs}
"""
# An episode's acts use at least BUSY_ACTS * BURN_S of CPU.
EPISODE_AT_LEAST_S = 10 * 0.03


def limits(evaluation_s: float) -> CpuLimits:
    return CpuLimits(step_s=1.0, episode_s=600.0, evaluation_s=evaluation_s)


def run(source, suite, out, ids, budget_s: float, force: bool = False):
    return evaluate(
        EvaluationRequest(
            source,
            suite,
            out_dir=out,
            scenario_ids=ids,
            jobs=1,
            sandbox=TEST_SANDBOX,
            cpu_limits=limits(budget_s),
            force=force,
        ),
        **evaluate_args(get_settings()),
    )


def done_episodes(summary) -> list[str]:
    return sorted(entry.id for entry in summary.scenarios if entry.status == "done")


def test_a_tiny_budget_stops_the_run_and_a_resume_keeps_counting(public_suite, tmp_path):
    ids = few_scenarios(public_suite, 3)
    source = write_policy(tmp_path / "busy", BUSY_POLICY)
    out = tmp_path / "out"

    # The first episode passes a budget smaller than one episode: no other starts.
    first = run(source, public_suite, out, ids, budget_s=0.1)
    assert not first.complete and len(done_episodes(first)) == 1
    (ran,) = done_episodes(first)
    used = read_agent_cpu(out)
    assert used is not None and used.over_budget
    assert used.used_s >= EPISODE_AT_LEAST_S and list(used.episodes) == [ran]

    # Resumed under the same budget: nothing more runs, the total stands.
    again = run(source, public_suite, out, ids, budget_s=0.1)
    assert done_episodes(again) == [ran]
    assert read_agent_cpu(out) == used

    # Resumed with room for one more episode only: the total goes on from the first run's.
    resumed = run(source, public_suite, out, ids, budget_s=used.used_s + 0.05)
    assert len(done_episodes(resumed)) == 2 and ran in done_episodes(resumed)
    total = read_agent_cpu(out)
    assert list(total.episodes) == done_episodes(resumed)
    assert total.episodes[ran] == used.episodes[ran]
    assert total.used_s >= used.used_s + EPISODE_AT_LEAST_S and total.over_budget

    # --force starts over: the old total is gone with the results.
    fresh = run(source, public_suite, out, ids, budget_s=0.1, force=True)
    assert done_episodes(fresh) == [ran]
    assert list(json.loads((out / AGENT_CPU_FILE).read_text())["episodes"]) == [ran]


def test_under_the_budget_every_episode_runs_and_its_cpu_is_counted(public_suite, tmp_path):
    ids = few_scenarios(public_suite, 2)
    source = write_policy(tmp_path / "busy", BUSY_POLICY)
    summary = run(source, public_suite, tmp_path / "out", ids, budget_s=600.0)
    assert summary.complete and done_episodes(summary) == sorted(ids)
    used = read_agent_cpu(tmp_path / "out")
    assert not used.over_budget and used.budget_s == 600.0
    assert all(seconds >= EPISODE_AT_LEAST_S for seconds in used.episodes.values())


def test_arena_evaluate_says_the_budget_was_passed_and_exits_1(public_suite, tmp_path, monkeypatch):
    from arena_command import app
    from tests.cli_runner import CliRunner

    ids = few_scenarios(public_suite, 2)
    source = write_policy(tmp_path / "busy", BUSY_POLICY)
    monkeypatch.setenv("ARENA_EVALUATION_CPU_S", "0.1")
    get_settings.cache_clear()
    try:
        command = ["evaluate", str(source), "--suite", str(public_suite), "--jobs", "1"]
        command += ["--sandbox", TEST_SANDBOX.value, "--out", str(tmp_path / "out")]
        for scenario_id in ids:
            command += ["--scenario", scenario_id]
        result = CliRunner().invoke(app, command)
    finally:
        get_settings.cache_clear()
    assert result.exit_code == 1, result.output
    output = " ".join(result.output.split())  # the console wraps long lines
    assert "CPU budget exceeded" in output and "budget of 0.1 s" in output
    assert "remaining episodes were not run" in output
    assert "re-run with the same --out to finish" not in output
