"""Summaries from outcomes and stored records, without the simulator."""

import json
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from arena.config import SandboxSettings
from arena.episodes import Episode
from arena.outcome import AgentOutcome, ScenarioStatus
from arena.suite import ManifestEntry, Suite, SuiteManifest
from evaluator.runner.results import record_path, score_outcomes, score_results_dir
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.scoring import ScoringProfile, load_profile
from evaluator.summary import read_summary, write_summary
from tests.evaluator.scoring.builders import AgentSpec, drive, write_record

PROFILE = load_profile()
SUITE = Suite(
    root=Path("unit"),
    manifest=SuiteManifest(
        suite="unit",
        scenarios=tuple(
            ManifestEntry(id=i, family=f)
            for i, f in [
                ("cruise_a", "cruise"),
                ("merge_a", "merge"),
                ("merge_b", "merge"),
                ("cruise_b", "cruise"),
            ]
        ),
    ),
    sha256="f" * 64,
)


def done(results_dir, scenario_id: str, agents: list[AgentSpec]) -> ScenarioOutcome:
    path = record_path(results_dir, scenario_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_record(path, scenario_id, agents)
    return ScenarioOutcome(scenario_id, ScenarioStatus.done, 0, (), path)


def simulator_error(scenario_id: str) -> ScenarioOutcome:
    return ScenarioOutcome(
        scenario_id, ScenarioStatus.simulator_error, 12, (), None, error="SUMO crashed"
    )


def weaving(n: int) -> dict[str, np.ndarray]:
    return drive(n, lane_offset=np.linspace(-1.0, 1.0, n), speed=14.5)


@pytest.fixture
def outcomes(tmp_path):
    return [
        done(tmp_path, "cruise_a", [AgentSpec(weaving(300), done_step=300)]),
        done(tmp_path, "merge_a", [AgentSpec(weaving(120), reason="collision")]),
        done(
            tmp_path,
            "merge_b",
            [AgentSpec(weaving(200), done_step=200), AgentSpec(weaving(90), reason="off_road")],
        ),
        simulator_error("cruise_b"),
    ]


def test_simulator_error_is_listed_and_not_charged(tmp_path, outcomes):
    summary = score_outcomes(outcomes, SUITE, PROFILE, submission="s" * 64)

    assert summary.uncharged == ("cruise_b",)
    assert summary.complete
    assert summary.metrics.completion == pytest.approx((0 + 1 + 0.5) / 3)
    assert summary.metrics.time == pytest.approx((300 + 800 + 800) / 3)
    assert summary.families["cruise"].time == 300
    assert summary.families["merge"].completion == 0.75
    entry = summary.scenarios[3]
    assert (entry.status, entry.metrics, entry.error) == ("simulator_error", None, "SUMO crashed")


def test_scenario_entries_follow_the_manifest_and_carry_agent_outcomes(tmp_path, outcomes):
    summary = score_outcomes(reversed(outcomes), SUITE, PROFILE, submission="s" * 64)
    assert [e.id for e in summary.scenarios] == [s.id for s in SUITE.scenarios]
    merge_b = summary.scenarios[2]
    assert [(a.id, a.reached_goal, a.reason, a.steps) for a in merge_b.agents] == [
        ("Agent_0", True, "reached_goal", 200),
        ("Agent_1", False, "off_road", 90),
    ]
    assert merge_b.metrics.completion == 0.5
    assert merge_b.terms["lc_off"] > 0


def test_unfinished_scenarios_are_pending_or_running(tmp_path, outcomes):
    summary = score_outcomes(
        outcomes[:1], SUITE, PROFILE, submission="s", running=[Episode("merge_b")]
    )
    assert [e.status for e in summary.scenarios] == ["done", "pending", "running", "pending"]
    assert not summary.complete
    assert summary.metrics.completion == 0.0


def test_rescoring_stored_records_gives_the_same_summary(tmp_path, outcomes):
    original = score_outcomes(outcomes, SUITE, PROFILE, submission="s" * 64)
    write_summary(original, tmp_path)
    assert score_results_dir(tmp_path, PROFILE) == original
    assert read_summary(tmp_path) == original


def test_rescoring_with_another_profile_changes_only_what_it_should(tmp_path, outcomes):
    write_summary(score_outcomes(outcomes, SUITE, PROFILE, submission="s"), tmp_path)
    lenient = ScoringProfile.model_validate(
        PROFILE.model_dump() | {"name": "lenient", "humanness_terms": ["distance_obs", "jerk"]}
    )
    rescored = score_results_dir(tmp_path, lenient)
    original = read_summary(tmp_path)
    assert rescored.profile.name == "lenient"
    assert rescored.metrics.completion == original.metrics.completion
    assert rescored.metrics.humanness < original.metrics.humanness


def test_agent_that_never_drove_is_charged_without_a_record(tmp_path):
    never = AgentOutcome(
        id="Agent_0", reached_goal=False, reason="init_timeout", steps=0, done_step=0
    )
    outcome = ScenarioOutcome("cruise_a", ScenarioStatus.done, 0, (never,), None)
    summary = score_outcomes([outcome], SUITE.select(["cruise_a"]), PROFILE, submission="s")
    assert (summary.metrics.completion, summary.metrics.time) == (1.0, 800)
    write_summary(summary, tmp_path)
    assert score_results_dir(tmp_path, PROFILE) == summary


def test_summary_json_has_the_documented_shape(tmp_path, outcomes):
    write_summary(score_outcomes(outcomes, SUITE, PROFILE, submission="s"), tmp_path)
    data = json.loads((tmp_path / "summary.json").read_text())
    assert {"submission", "suite", "manifest_hash", "profile", "metrics", "families"} <= set(data)
    assert set(data["metrics"]) == {"completion", "time", "humanness", "rules"}
    scenario = data["scenarios"][0]
    assert {"id", "family", "status", "steps", "agents"} <= set(scenario)
    assert {"id", "reached_goal", "reason", "steps"} <= set(scenario["agents"][0])


def test_broken_record_is_reported_uncharged_not_scored(tmp_path):
    from evaluator.runner.evaluate import ResultsFolder

    folder = ResultsFolder(
        tmp_path,
        SUITE.select(["cruise_a", "merge_a"]),
        PROFILE,
        "s",
        cpu_limits=SandboxSettings().cpu_limits,
    )
    (tmp_path / "logs").mkdir()
    folder.resume()
    good = done(tmp_path, "cruise_a", [AgentSpec(weaving(50), done_step=50)])
    broken = record_path(tmp_path, "merge_a")
    broken.write_bytes(b"not an npz")
    folder.record(good)
    folder.record(ScenarioOutcome("merge_a", ScenarioStatus.done, 10, (), broken))
    folder.summary()

    summary = read_summary(tmp_path)
    assert summary.uncharged == ("merge_a",)
    assert summary.scenarios[1].status == "evaluator_error"
    assert "unusable episode record" in summary.scenarios[1].error
    assert summary.metrics.time == 50


EPISODE_SUITE = Suite(
    root=Path("unit"),
    manifest=SuiteManifest(
        suite="unit",
        scenarios=(
            ManifestEntry(id="cruise_a", family="cruise"),
            ManifestEntry(id="replay_a", family="replay", reactive=False),
        ),
    ),
    sha256="e" * 64,
)


def done_episode(results_dir, scenario_id, index, agents) -> ScenarioOutcome:
    name = Episode(scenario_id, index).name
    path = record_path(results_dir, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_record(path, scenario_id, agents)
    return ScenarioOutcome(scenario_id, ScenarioStatus.done, 0, (), path, episode=index)


@pytest.fixture
def episode_outcomes(tmp_path):
    return [
        done_episode(tmp_path, "cruise_a", 0, [AgentSpec(weaving(300), done_step=300)]),
        done_episode(tmp_path, "cruise_a", 1, [AgentSpec(weaving(100), reason="collision")]),
        done_episode(tmp_path, "replay_a", 0, [AgentSpec(weaving(200), done_step=200)]),
    ]


def test_a_scenario_run_twice_scores_the_mean_of_its_episodes(episode_outcomes):
    summary = score_outcomes(
        episode_outcomes, EPISODE_SUITE, PROFILE, submission="s", episodes_per_scenario=2
    )
    cruise, replay = summary.scenarios
    assert [e.index for e in cruise.episodes] == [0, 1]
    assert replay.episodes is None  # a non-reactive replay runs once
    assert cruise.metrics.completion == 0.5
    assert cruise.metrics.time == (300 + 800) / 2
    assert cruise.steps == 300 + 100
    # Each scenario counts once in the suite, however many episodes it ran.
    assert summary.metrics.completion == pytest.approx((0.5 + 0.0) / 2)
    assert summary.metrics.time == pytest.approx((550 + 200) / 2)
    # Humanness stays a mean over agent-steps: the episodes' sums over their steps.
    alone = score_outcomes(
        episode_outcomes[:2],
        EPISODE_SUITE.select(["cruise_a"]),
        PROFILE,
        submission="s",
        episodes_per_scenario=2,
    )
    first = score_outcomes(
        episode_outcomes[:1], EPISODE_SUITE.select(["cruise_a"]), PROFILE, submission="s"
    )
    second = score_outcomes(
        [replace(episode_outcomes[1], episode=0)],
        EPISODE_SUITE.select(["cruise_a"]),
        PROFILE,
        submission="s",
    )
    steps = (300, 100)
    expected = (first.metrics.humanness * steps[0] + second.metrics.humanness * steps[1]) / 400
    assert alone.metrics.humanness == pytest.approx(expected)


def test_a_scenario_is_charged_once_all_its_episodes_are_done(tmp_path, episode_outcomes):
    partial = score_outcomes(
        episode_outcomes[:1] + episode_outcomes[2:],
        EPISODE_SUITE,
        PROFILE,
        submission="s",
        episodes_per_scenario=2,
    )
    assert partial.scenarios[0].status == "running"  # started, one episode to go
    assert [e.status for e in partial.scenarios[0].episodes] == ["done", "pending"]
    assert partial.metrics.completion == 0.0  # the replay alone
    crashed = replace(episode_outcomes[1], status=ScenarioStatus.simulator_error, error="SUMO")
    ours = score_outcomes(
        [episode_outcomes[0], crashed, episode_outcomes[2]],
        EPISODE_SUITE,
        PROFILE,
        submission="s",
        episodes_per_scenario=2,
    )
    assert ours.uncharged == ("cruise_a",)
    assert ours.scenarios[0].error == "episode 1: SUMO"


def test_one_episode_summaries_keep_their_shape_and_several_rescore_alike(
    tmp_path, episode_outcomes
):
    once = score_outcomes(
        [episode_outcomes[0], episode_outcomes[2]], EPISODE_SUITE, PROFILE, submission="s"
    )
    write_summary(once, tmp_path)
    data = json.loads((tmp_path / "summary.json").read_text())
    assert "episodes_per_scenario" not in data
    assert all("episodes" not in entry for entry in data["scenarios"])

    twice = score_outcomes(
        episode_outcomes, EPISODE_SUITE, PROFILE, submission="s", episodes_per_scenario=2
    )
    write_summary(twice, tmp_path)
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["episodes_per_scenario"] == 2
    assert len(data["scenarios"][0]["episodes"]) == 2
    assert score_results_dir(tmp_path, PROFILE) == twice
    assert twice.completion_samples() == [[0.0, 1.0], [0.0]]
    interval = twice.completion_interval()
    assert interval.low <= twice.metrics.completion <= interval.high


def test_checkpoints_space_summary_writes_by_their_cost(tmp_path, monkeypatch):
    """A long run's summary.json grows with every episode; rewriting it after each one made the
    run quadratic. Checkpoints wait CHECKPOINT_SPACING times the last write's cost."""
    evaluate = sys.modules["evaluator.runner.evaluate"]
    now = [0.0]

    def clock() -> float:  # each reading 10 ms later: every write "costs" 10 ms
        now[0] += 0.010
        return now[0]

    monkeypatch.setattr(evaluate, "monotonic", clock)
    folder = evaluate.ResultsFolder(
        tmp_path, SUITE, PROFILE, "s", 40, cpu_limits=SandboxSettings().cpu_limits
    )
    (tmp_path / "logs").mkdir()
    folder.resume()
    good = done(tmp_path, "cruise_a", [AgentSpec(weaving(50), done_step=50)])
    written, seen = 0, 0
    for k in range(40):
        folder.record(replace(good, episode=k))
        folder.checkpoint()
        shown = read_summary(tmp_path).scenarios[0].episodes
        done_now = sum(e.status == "done" for e in shown)
        written += done_now != seen
        seen = done_now
    # One clock reading per checkpoint (10 ms) and a write costing 10 ms is followed by
    # 190 ms without one: about one write in twenty checkpoints.
    assert 2 <= written <= 4, written
    assert seen < 40
    folder.summary()  # the end of a run always writes
    assert sum(e.status == "done" for e in read_summary(tmp_path).scenarios[0].episodes) == 40


def test_every_results_file_is_replaced_whole_never_rewritten_in_place(tmp_path):
    """An evaluation killed at any instant (a worker's SIGKILL) leaves each file of its results
    folder either as it was or as it became, never cut short: each write goes to a new file that
    replaces the old one, which stays whole for whoever has it open. A killed run once left an
    empty agent_cpu.json, and its resume failed on it."""
    evaluate = sys.modules["evaluator.runner.evaluate"]
    folder = evaluate.ResultsFolder(
        tmp_path, SUITE, PROFILE, "s", 1, cpu_limits=SandboxSettings().cpu_limits
    )
    (tmp_path / "logs").mkdir()
    folder.resume()
    outcome = done(tmp_path, "cruise_a", [AgentSpec(weaving(50), done_step=50)])
    names = ["summary.json", "timings.json", "agent_cpu.json", "scores.json", "logs/cruise_a.txt"]
    folder.record(outcome)
    folder.charge_cpu(outcome)
    folder.summary()
    # Held open, the old files keep their inodes: a rewrite in place would show in them.
    before = {name: (tmp_path / name).read_bytes() for name in names}
    held = {name: (tmp_path / name).open("rb") for name in names}
    try:
        folder.record(replace(outcome, log="the same episode, recorded again"))
        folder.charge_cpu(replace(outcome, agent_cpu_s=1.5))
        folder.summary()
        for name, old in held.items():
            assert old.read() == before[name], name
            assert os.fstat(old.fileno()).st_ino != (tmp_path / name).stat().st_ino, name
    finally:
        for old in held.values():
            old.close()
    assert before["agent_cpu.json"] != (tmp_path / "agent_cpu.json").read_bytes()
