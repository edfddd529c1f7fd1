"""The participant's edit-and-evaluate loop through `arena evaluate`: results per submission
version, --force, tracebacks in the terminal (identical ones once), exit codes, and a run that
stops early when the agent cannot start."""

import json

import pytest

from arena_command import app
from sim.compiled import core_status
from tests.cli_runner import CliRunner
from tests.evaluator.runner.conftest import write_policy

SCENARIOS = ["p000_left_turn_t_low", "p001_left_turn_t_rotated_mid", "p002_turn_c_left_turn_c_low"]
KEEP_LANE = """
class Policy:
    def act(self, obs):
        return {k: [SPEED, 0.0] for k in obs}
"""


def evaluate(*args: str, scenarios=SCENARIOS[:1]):
    selected = [arg for s in scenarios for arg in ("--scenario", s)]
    command = ["evaluate", *args, *selected, "--sandbox", "process", "--jobs", "1"]
    return CliRunner().invoke(app, command)


@pytest.mark.slow
def test_each_version_keeps_its_results_and_force_replaces_them(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    agent = write_policy(tmp_path / "agent", KEEP_LANE.replace("SPEED", "8.0"))
    first = evaluate(str(agent))
    assert first.exit_code == 0, first.output
    agent.joinpath("policy.py").write_text(KEEP_LANE.replace("SPEED", "9.0"))
    second = evaluate(str(agent))
    assert second.exit_code == 0, second.output  # the edited agent no longer refuses the folder
    versions = sorted(p.name for p in (tmp_path / "arena-results" / "agent").iterdir())
    assert len(versions) == 2
    for version in versions:
        assert (tmp_path / "arena-results" / "agent" / version / "summary.json").exists()
    # An explicit --out holding another version is refused unless --force replaces it.
    out = tmp_path / "mine"
    assert evaluate(str(agent), "--out", str(out)).exit_code == 0
    agent.joinpath("policy.py").write_text(KEEP_LANE.replace("SPEED", "7.0"))
    refused = evaluate(str(agent), "--out", str(out))
    assert refused.exit_code == 2 and "--force" in refused.output
    before = json.loads((out / "summary.json").read_text())["submission"]
    forced = evaluate(str(agent), "--out", str(out), "--force", "--json")
    assert forced.exit_code == 0, forced.output
    after = json.loads((out / "summary.json").read_text())["submission"]
    assert after == json.loads(forced.stdout)["submission"] != before


def test_an_agent_that_cannot_start_stops_the_run_with_one_error(tmp_path):
    agent = write_policy(tmp_path / "agent", "import not_a_package_anywhere\n" + KEEP_LANE)
    result = evaluate(str(agent), "--out", str(tmp_path / "out"), scenarios=SCENARIOS)
    assert result.exit_code == 1
    assert f"simulator core: {core_status()}\n" in result.output  # compiled, or why not
    assert result.output.count("your agent could not start") == 1
    assert result.output.count("ModuleNotFoundError") == 1
    assert "requirements.txt" in result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    ran = [s for s in summary["scenarios"] if s["status"] == "done"]
    assert len(ran) == 2 and not summary["complete"]  # the third never started


@pytest.mark.slow
def test_identical_tracebacks_are_printed_once_with_their_scenarios(tmp_path):
    body = """
class Policy:
    def act(self, obs):
        if obs[next(iter(obs))]["step_count"] >= 3:
            raise RuntimeError("lost my way")
        return {k: [5.0, 0.0] for k in obs}
"""
    agent = write_policy(tmp_path / "agent", body)
    result = evaluate(str(agent), "--out", str(tmp_path / "out"), scenarios=SCENARIOS[:2])
    assert result.exit_code == 1
    assert result.output.count("RuntimeError: lost my way") == 1
    assert "failure (2 scenarios) in p000_left_turn_t_low, p001_left_turn_t_rotated_mid" in (
        result.output.replace("\n", " ")
    )
    # The step in the summary line is the step in the log.
    line = next(x for x in result.output.splitlines() if x.startswith("agent failure p000"))
    log = (tmp_path / "out" / "logs" / "p000_left_turn_t_low.txt").read_text()
    assert line.split(": ", 1)[1] in log


def test_a_bad_action_shows_its_detail_and_fails_the_exit_code(tmp_path):
    agent = write_policy(tmp_path / "agent", KEEP_LANE.replace("[SPEED, 0.0]", "[1.0, 2.0, 3.0]"))
    result = evaluate(str(agent), "--out", str(tmp_path / "out"))
    assert result.exit_code == 1
    assert "Agent_0 invalid_action at step 1 (0 steps driven)" in result.output


def test_scenarios_list_public_plain_and_json():
    plain = CliRunner().invoke(app, ["scenarios", "list", "public"])
    assert plain.exit_code == 0, plain.output
    lines = plain.output.splitlines()
    header = lines[1].split("\t")
    assert header[:2] == ["id", "family"]
    ids = [line.split("\t")[0] for line in lines[2:]]
    assert "p000_left_turn_t_low" in ids  # whole, never cut to "p000_…"
    listed = json.loads(CliRunner().invoke(app, ["scenarios", "list", "public", "--json"]).stdout)
    assert [row["id"] for row in listed] == ids
    assert len(listed[0]["hash"]) == 64


def test_agent_text_with_a_lone_surrogate_is_written_and_printed(tmp_path):
    """Its exception message crashed `arena evaluate` writing the episode's log
    (UnicodeEncodeError): every local sink of agent text goes through arena.neutralise."""
    body = """
class Policy:
    def act(self, obs):
        raise ValueError("bad \\ud800 text")
"""
    agent = write_policy(tmp_path / "agent", body)
    result = evaluate(str(agent), "--out", str(tmp_path / "out"))
    assert result.exit_code == 1, result.output
    assert "ValueError: bad \ufffd" in result.output  # one per byte of its UTF-8 form
    log = (tmp_path / "out" / "logs" / f"{SCENARIOS[0]}.txt").read_text(encoding="utf-8")
    assert "ValueError: bad \ufffd" in log


def test_an_episode_not_charged_fails_the_exit_code_and_says_why(tmp_path):
    """It exited 0 with a table of 0 scenarios: now 3, with which scenario failed on our side,
    why, and what to do."""
    from tests.sim.builders import make_scenario

    suite = tmp_path / "suite"
    make_scenario(suite / "broken")
    for net in (suite / "broken").glob("*.net.xml"):
        net.write_text("<net><edge id=")  # SUMO cannot load it: ours
    entries = [{"id": "broken", "family": "cruise"}]
    (suite / "manifest.json").write_text(json.dumps({"suite": "unit", "scenarios": entries}))
    agent = write_policy(tmp_path / "agent", KEEP_LANE.replace("SPEED", "8.0"))
    result = evaluate(
        str(agent), "--suite", str(suite), "--out", str(tmp_path / "out"), scenarios=[]
    )
    assert result.exit_code == 3, result.output
    assert "not charged broken (simulator_error)" in result.output
    assert "failed on our side" in result.output and "not of your agent" in result.output
    assert "completion" not in result.output  # no table of scores of nothing
