"""Whose an episode's end is (arena.outcome.verdict, docs/protocol.md "Whose failure it is"): the
rule as a table, then every failure point driven for real through run_scenario on every backend.
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from pathlib import Path

import pytest

from arena.config import SandboxKind, Settings
from arena.errors import ParticipantError
from arena.outcome import Facts, Process, ScenarioStatus, Verdict, verdict
from evaluator.runner import run_scenario
from tests.evaluator.runner.conftest import write_policy
from tests.evaluator.sandbox.conftest import usable
from tests.settings import with_fields


@pytest.mark.parametrize(
    ("facts", "expected"),
    [
        (Facts(None, team_loaded=True), Verdict.driving),
        (Facts(None, team_loaded=False), Verdict.driving),
        # Nothing of the team's loaded: whatever failed is ours.
        (Facts(Process.team, team_loaded=False), Verdict.ours),
        (Facts(Process.ours, team_loaded=False, team_healthy=False), Verdict.ours),
        # Loaded: the team's, unless our process failed while theirs was healthy.
        (Facts(Process.team, team_loaded=True), Verdict.agent),
        (Facts(Process.team_files, team_loaded=True), Verdict.agent),
        (Facts(Process.ours, team_loaded=True), Verdict.ours),
        (Facts(Process.ours, team_loaded=True, team_healthy=False), Verdict.agent),
    ],
)
def test_the_rule(facts, expected):
    assert verdict(facts) is expected


# --- every failure point, for real --------------------------------------------------------------

DRIVE = """
import time

class Policy:
    def act(self, obs):
        time.sleep({pause})
        return {{agent_id: [10.0, 0] for agent_id in obs}}
"""
# A submission module shadowing numpy, which the runtime imported before hello until it said
# hello first: its exit was "ours", uncharged and repeatable without limit.
SHADOWED_NUMPY = "import os\nos._exit(3)\n"
IMPORTS_NUMPY = "import numpy\n" + DRIVE.format(pause=0)
FAILS_IN_RESET = (
    DRIVE.format(pause=0)
    + """
    def reset(self):
        raise ValueError("reset")
"""
)
FAILS_IN_ACT = """
class Policy:
    def act(self, obs):
        raise ValueError("act")
"""
# The runtime's close answers before the interpreter exits: the exit handler fails after it.
FAILS_IN_CLOSE = "import atexit, os\natexit.register(lambda: os._exit(7))\n" + DRIVE.format(pause=0)

KINDS = [
    pytest.param(SandboxKind.process, marks=pytest.mark.slow, id="process"),
    pytest.param(SandboxKind.bubblewrap, marks=pytest.mark.bwrap, id="bubblewrap"),
    pytest.param(SandboxKind.docker, marks=pytest.mark.docker, id="docker"),
]


@pytest.fixture(scope="module")
def settings(tmp_path_factory) -> Settings:
    return with_fields(
        Settings(),
        storage={"data_dir": tmp_path_factory.mktemp("data")},
        sandbox={"init_timeout_s": 30.0, "warm_agents": False},
    )


@pytest.fixture(params=KINDS)
def kind(request, settings) -> SandboxKind:
    return usable(request.param, settings)


def _prepare(source: Path, dest: Path, settings: Settings):
    from submissions.intake import prepare_submission

    return prepare_submission(
        source, dest, settings.intake, settings.sandbox, settings.storage.resolved_data_dir
    )


def _scenario(folder: Path, *, broken: bool = False) -> Path:
    from tests.sim.builders import make_scenario

    make_scenario(folder)
    if broken:  # SUMO cannot load the map
        for net in folder.glob("*.net.xml"):
            net.write_text("<net><edge id=")
    return folder


def _run(tmp_path, settings, kind, body, *, files=None, broken=False, config=None):
    source = write_policy(tmp_path / "agent", body)
    for name, text in (files or {}).items():
        (source / name).write_text(text)
    submission = _prepare(source, tmp_path / "prepared", settings)
    return run_scenario(
        submission,
        _scenario(tmp_path / "cruise", broken=broken),
        tmp_path / "records",
        config=config or settings.sandbox,
        data_dir=settings.storage.resolved_data_dir,
        sandbox=kind,
    )


def test_a_sandbox_silent_before_hello_is_ours(tmp_path, settings, kind):
    """No hello within the start-up limit: only our runtime had run (it says hello before it
    reads anything of the team's)."""
    hasty = settings.sandbox.model_copy(update={"runtime_start_timeout_s": 0.001})
    outcome = _run(tmp_path, settings, kind, DRIVE.format(pause=0), config=hasty)
    assert outcome.verdict is Verdict.ours, outcome.log
    assert outcome.status is ScenarioStatus.evaluator_error and outcome.attempts == 2
    assert "sandbox_error" in outcome.log


@pytest.mark.slow
def test_a_sandbox_ending_before_hello_is_ours(tmp_path, settings):
    """Too little memory for the interpreter (the process backend's rlimit; the isolating
    backends' cgroups let an interpreter start): it ends before the runtime says hello."""
    tiny = settings.sandbox.model_copy(update={"agent_memory_bytes": 8 * 1024**2})
    outcome = _run(tmp_path, settings, SandboxKind.process, DRIVE.format(pause=0), config=tiny)
    assert outcome.verdict is Verdict.ours, outcome.log
    assert outcome.status is ScenarioStatus.evaluator_error and outcome.attempts == 2
    assert "before the runner started" in outcome.error


def test_an_exit_in_an_import_is_the_teams(tmp_path, settings, kind):
    outcome = _run(tmp_path, settings, kind, IMPORTS_NUMPY, files={"numpy.py": SHADOWED_NUMPY})
    assert outcome.verdict is Verdict.agent, outcome.log
    assert outcome.status is ScenarioStatus.done and outcome.attempts == 1
    assert [a.reason for a in outcome.agents] == ["agent_exited"]


@pytest.mark.parametrize(("body", "where"), [(FAILS_IN_RESET, "reset"), (FAILS_IN_ACT, "act")])
def test_an_exception_in_reset_or_act_is_the_teams(tmp_path, settings, kind, body, where):
    outcome = _run(tmp_path, settings, kind, body)
    assert outcome.verdict is Verdict.agent, outcome.log
    assert outcome.status is ScenarioStatus.done and outcome.attempts == 1
    assert [a.reason for a in outcome.agents] == ["agent_error"]
    assert f"ValueError: {where}" in outcome.log


def test_a_failing_close_keeps_the_driving_verdict(tmp_path, settings, kind):
    outcome = _run(tmp_path, settings, kind, FAILS_IN_CLOSE)
    assert outcome.verdict is Verdict.driving, outcome.log
    assert outcome.status is ScenarioStatus.done and outcome.attempts == 1


def test_the_simulator_failing_under_a_healthy_agent_is_ours(tmp_path, settings, kind):
    outcome = _run(tmp_path, settings, kind, DRIVE.format(pause=0), broken=True)
    assert outcome.verdict is Verdict.ours
    assert outcome.status is ScenarioStatus.simulator_error and outcome.attempts == 2


def test_the_worker_killing_its_episode_under_a_healthy_agent_is_ours(tmp_path, settings, kind):
    """The evaluating process ends the episode's process mid-episode (a worker shutting down,
    the kernel's OOM killer on our side): the agent was healthy, so it is ours."""
    stop = threading.Event()

    def kill_episodes() -> None:
        while not stop.is_set():
            for child in multiprocessing.active_children():
                if child.name.startswith("episode-"):
                    time.sleep(1.0)  # mid-episode: the agent has said hello and driven
                    child.kill()
            time.sleep(0.05)

    killer = threading.Thread(target=kill_episodes, daemon=True)
    killer.start()
    try:
        outcome = _run(tmp_path, settings, kind, DRIVE.format(pause=0.2))
    finally:
        stop.set()
        killer.join()
    assert outcome.verdict is Verdict.ours, outcome.log
    assert outcome.status is ScenarioStatus.simulator_error and outcome.attempts == 2


def test_the_host_parser_failing_on_team_files_is_the_teams(tmp_path, settings):
    """An agent.yaml nested deep enough to break a parser: the failure is the team's
    (a ParticipantError, never retried), whichever process parsed it."""
    source = write_policy(tmp_path / "agent", DRIVE.format(pause=0))
    (source / "agent.yaml").write_text("a: " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(ParticipantError):
        _prepare(source, tmp_path / "prepared", settings)
    assert verdict(Facts(Process.team_files, team_loaded=True)) is Verdict.agent
