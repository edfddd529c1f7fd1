"""`arena score` and `arena replay` on a results folder built from synthetic records."""

import json
from pathlib import Path

import pytest

from arena.outcome import ScenarioStatus
from arena.suite import ManifestEntry, Suite, SuiteManifest
from arena_command import app
from evaluator.runner.results import record_path, score_outcomes
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.scoring import load_profile
from evaluator.summary import read_summary, write_summary
from tests.cli_runner import CliRunner
from tests.evaluator.scoring.builders import AgentSpec, drive, write_record

SUITE = Suite(
    root=Path("unit"),
    manifest=SuiteManifest(
        suite="unit",
        scenarios=(ManifestEntry(id="a", family="cruise"), ManifestEntry(id="b", family="merge")),
    ),
    sha256="f" * 64,
)


def write_results(folder, specs) -> Path:
    outcomes = []
    for scenario_id, spec in specs:
        path = record_path(folder, scenario_id)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_record(path, scenario_id, [spec])
        outcomes.append(ScenarioOutcome(scenario_id, ScenarioStatus.done, 0, (), path))
    write_summary(score_outcomes(outcomes, SUITE, load_profile(), submission="s" * 64), folder)
    return folder


@pytest.fixture
def results(tmp_path):
    return write_results(
        tmp_path,
        (
            ("a", AgentSpec(drive(300, lane_offset=0.5), done_step=300)),
            ("b", AgentSpec(drive(120), reason="collision")),
        ),
    )


def test_score_prints_the_metrics_table_and_failures(results):
    result = CliRunner().invoke(app, ["score", str(results)])
    assert result.exit_code == 0, result.output
    assert "completion" in result.output and "merge" in result.output
    # A collision is a driving outcome, not a failure of the program.
    assert "goal not reached b: Agent_0 collision at step 120" in result.output
    assert "agent failure" not in result.output.replace("0 by an agent failure", "")
    assert "episodes: 1 reached the goal, 1 ended by a driving outcome, 0 by an agent failure" in (
        result.output
    )


def test_compare_two_results_folders_side_by_side(results, tmp_path):
    other = write_results(
        tmp_path / "other",
        (
            ("a", AgentSpec(drive(250), done_step=250)),
            ("b", AgentSpec(drive(200), done_step=200)),
        ),
    )
    result = CliRunner().invoke(app, ["compare", str(results), str(other)])
    assert result.exit_code == 0, result.output
    lines = [line.split("\t") for line in result.output.splitlines()]
    completion = next(row for row in lines if row[0] == "completion")
    # Two scenarios, B better on one: paired over them, the difference is -1 or 0 per draw.
    assert completion == ["completion", "0.5000", "0.0000", "-0.5000", "[-1.0000, +0.0000]"]
    ahead = next(row for row in lines if row[0] == "B ranks ahead of A")[-1]
    assert ahead.endswith("of resamples over 2 shared scenarios")
    assert any(row[0] == "completion 95% interval" for row in lines)
    merge = next(row for row in lines if row[0] == "merge")
    assert merge[1:3] == ["1.0000", "0.0000"]
    # Only the episode that ended differently: b collided in A, reached its goal in B.
    assert "1 episode(s) ended differently" in result.output
    assert ["b", "collision", "reached_goal"] in lines
    assert not any(row[0] == "a" and len(row) == 3 for row in lines)
    document = json.loads(
        CliRunner().invoke(app, ["compare", str(results), str(other), "--json"]).stdout
    )
    assert document["differing_outcomes"] == [
        {"episode": "b", "a": "collision", "b": "reached_goal"}
    ]
    missing = CliRunner().invoke(app, ["compare", str(results), str(tmp_path / "nope")])
    assert missing.exit_code == 2 and "has no summary.json" in missing.output


def test_score_json_is_the_rewritten_summary(results):
    result = CliRunner().invoke(app, ["score", str(results), "--json"])
    assert result.exit_code == 0
    printed = json.loads(result.stdout)
    assert printed == read_summary(results).to_dict()
    assert printed["metrics"]["completion"] == 0.5
    assert printed["metrics"]["time"] == 550.0


def test_score_refuses_an_unknown_profile_without_touching_the_summary(results):
    before = (results / "summary.json").read_bytes()
    result = CliRunner().invoke(app, ["score", str(results), "--profile", "nope"])
    assert result.exit_code == 2
    assert "unknown scoring profile 'nope'" in result.output
    assert (results / "summary.json").read_bytes() == before


def test_replay_writes_a_picture(results, tmp_path):
    out = tmp_path / "b.svg"
    args = ["replay", str(results), "b", "--format", "svg", "--out", str(out)]
    result = CliRunner().invoke(app, [*args, "--suite", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "collision at step 120" in out.read_text()


def test_score_per_scenario_adds_a_row_per_scenario(results):
    plain = CliRunner().invoke(app, ["score", str(results)])
    detailed = CliRunner().invoke(app, ["score", str(results), "--per-scenario"])
    # Not a terminal: one tab-separated line per row.
    rows = [line.split("\t") for line in detailed.output.splitlines() if line.startswith("b\t")]
    assert len(rows) == 1 and rows[0][2:4] == ["1.0000", "800.0"]
    assert rows[0][-1] == "collision"  # the reason column
    assert not [line for line in plain.output.splitlines() if line.startswith("b\t")]


def test_a_resumed_runs_progress_counts_the_episodes_it_kept():
    """`failures 0` above 19 failed lines was a resumed run counting from zero."""
    from arena.outcome import AgentOutcome
    from arena.terminal import make_console
    from evaluator.cli import _RichProgress

    def outcome(name, reason, status=ScenarioStatus.done):
        agent = AgentOutcome(
            id="Agent_0", reached_goal=reason == "reached_goal", reason=reason, steps=5, done_step=5
        )
        return ScenarioOutcome(name, status, 5, (agent,), None)

    progress = _RichProgress(make_console())
    kept = [outcome("a", "collision"), outcome("b", "agent_error"), outcome("c", "reached_goal")]
    progress.started(5, kept)
    progress.finished(outcome("d", "step_timeout"))
    progress.stop()
    assert progress.counts == {"faults": 2, "missed": 1, "uncharged": 0}


def test_arena_evaluate_writes_figures_as_every_other_view_does():
    """One rounding everywhere: a half at the last decimal goes away from zero (0.53125 reads
    0.5313 here, on the pages and in the admin CLI), nothing measured reads "—"."""
    from evaluator.cli import format_metrics
    from evaluator.scoring import Metrics

    measured = Metrics(completion=0.53125, time=412.25, humanness=None, rules=0.0)
    assert format_metrics(measured) == ("0.5313", "412.3", "—", "0.0000")
