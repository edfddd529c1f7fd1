"""`arena score` and `arena replay` on a results folder built from synthetic records."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from arena.cli import app
from arena.outcome import ScenarioStatus
from arena.suite import ManifestEntry, Suite, SuiteManifest
from evaluator.runner.results import record_path, score_outcomes
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.scoring import load_profile
from evaluator.summary import read_summary, write_summary
from tests.evaluator.scoring.builders import AgentSpec, drive, write_record

SUITE = Suite(
    root=Path("unit"),
    manifest=SuiteManifest(
        suite="unit",
        scenarios=(ManifestEntry(id="a", family="cruise"), ManifestEntry(id="b", family="merge")),
    ),
    sha256="f" * 64,
)


@pytest.fixture
def results(tmp_path):
    outcomes = []
    for scenario_id, spec in (
        ("a", AgentSpec(drive(300, lane_offset=0.5), done_step=300)),
        ("b", AgentSpec(drive(120), reason="collision")),
    ):
        path = record_path(tmp_path, scenario_id)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_record(path, scenario_id, [spec])
        outcomes.append(ScenarioOutcome(scenario_id, ScenarioStatus.done, 0, (), path))
    write_summary(score_outcomes(outcomes, SUITE, load_profile(), submission="s" * 64), tmp_path)
    return tmp_path


def test_score_prints_the_metrics_table_and_failures(results):
    result = CliRunner().invoke(app, ["score", str(results)])
    assert result.exit_code == 0, result.output
    assert "completion" in result.output and "merge" in result.output
    assert "b: Agent_0 collision at step 120" in result.output


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
    assert not [line for line in plain.output.splitlines() if line.startswith("b\t")]
