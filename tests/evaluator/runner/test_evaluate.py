"""End-to-end runs of `evaluate` on the public suite: real simulator, real sandboxed agents."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from arena.config import get_settings
from arena.episodes import traffic_seed
from arena.examples import example_dir
from arena.outcome import ScenarioStatus
from arena.scenario import load_scenario
from arena.suite import load_suite
from evaluator.runner import EvaluationRequest, evaluate, score_results_dir
from evaluator.scoring import DEFAULT_PROFILE, load_profile
from evaluator.summary import read_summary
from tests.evaluator.runner.conftest import TEST_SANDBOX, write_policy
from tests.settings import evaluate_args

pytestmark = pytest.mark.slow

# Lane keeping at a steady 8 m/s; crashes on purpose in the scenario whose start is CRASH_AT.
STEADY_POLICY = """
CRASH_AT = {crash_at!r}


class Policy:
    def act(self, obs):
        actions = {{}}
        for agent_id, o in obs.items():
            start = o["ego_vehicle_state"]["mission"]["start"]
            if CRASH_AT and abs(start[0] - CRASH_AT[0]) + abs(start[1] - CRASH_AT[1]) < 1e-3:
                raise RuntimeError("deliberate crash in this scenario")
            actions[agent_id] = [8.0, 0]
        return actions
"""


def few_scenarios(suite: Path, n: int) -> list[str]:
    """``n`` scenarios of different families, single-agent first, for short runs."""
    manifest = json.loads((suite / "manifest.json").read_text())
    chosen, families = [], set()
    for item in sorted(manifest["scenarios"], key=lambda s: (s["agents"], s["id"])):
        if item["family"] not in families:
            chosen.append(item["id"])
            families.add(item["family"])
    return chosen[:n]


def steady(tmp_path: Path, crash_at=None) -> Path:
    return write_policy(tmp_path / "steady", STEADY_POLICY.format(crash_at=crash_at))


def run(source: Path, suite: Path, out: Path, ids=None, jobs: int = 2):
    return evaluate(
        EvaluationRequest(
            source, suite, out_dir=out, scenario_ids=ids, jobs=jobs, sandbox=TEST_SANDBOX
        ),
        **evaluate_args(get_settings()),
    )


def test_same_submission_twice_gives_identical_summary_and_records(public_suite, tmp_path):
    ids = few_scenarios(public_suite, 2)
    source = steady(tmp_path)
    first = run(source, public_suite, tmp_path / "a", ids)
    second = run(source, public_suite, tmp_path / "b", ids, jobs=1)
    # The simulator processes of an evaluation end with it (sim.episode_workers), not an idle
    # time later, though this process goes on.
    assert not [p for p in multiprocessing.active_children() if p.name == "episode-worker"]

    assert first.complete and first.metrics is not None
    summary_a = (tmp_path / "a" / "summary.json").read_bytes()
    assert summary_a == (tmp_path / "b" / "summary.json").read_bytes()
    for scenario_id in ids:
        record = f"records/{scenario_id}.npz"
        assert (tmp_path / "a" / record).read_bytes() == (tmp_path / "b" / record).read_bytes()
    # re-scoring the stored records reproduces the summary without simulating
    assert score_results_dir(tmp_path / "a", load_profile()) == second
    # ...and its manifest: what the summary depends on, pinned.
    manifest = first.manifest
    assert manifest.suite_hash == first.manifest_hash
    for scenario_id in ids:
        seed = traffic_seed(scenario_id, load_scenario(public_suite / scenario_id).seed, 0)
        assert manifest.scenarios[scenario_id].seeds == (seed,)
    (environment,) = manifest.environments
    assert environment.sandbox == TEST_SANDBOX.value
    assert environment.python and environment.sumo != "unknown"
    assert environment.agent_stack["numpy"]  # as the agent's runtime imported it


def test_crash_in_one_scenario_still_scores_every_other(public_suite, tmp_path):
    from arena.scenario import load_scenario

    ids = few_scenarios(public_suite, 3)
    start = load_scenario(public_suite / ids[1]).missions[0].start
    summary = run(steady(tmp_path, crash_at=start[:2]), public_suite, tmp_path / "out", ids)

    entries = {entry.id: entry for entry in summary.scenarios}
    crashed = entries[ids[1]]
    assert crashed.status == ScenarioStatus.done  # charged, not excused
    assert [a.reason for a in crashed.agents] == ["agent_error"]
    assert crashed.metrics.completion == 1.0
    for scenario_id in (ids[0], ids[2]):
        assert entries[scenario_id].status == ScenarioStatus.done
        assert entries[scenario_id].agents[0].reason != "agent_error"
        assert entries[scenario_id].steps > 1
    assert summary.uncharged == ()
    log = (tmp_path / "out" / "logs" / f"{ids[1]}.txt").read_text()
    assert "deliberate crash in this scenario" in log


def test_killed_evaluation_resumes_only_the_missing_scenarios(public_suite, tmp_path):
    ids = few_scenarios(public_suite, 3)
    source, out = steady(tmp_path), tmp_path / "out"
    command = [
        sys.executable,
        "-c",
        "from arena_command import app; app()",
        "evaluate",
        str(source),
        "--suite",
    ]
    command += [
        str(public_suite),
        "--jobs",
        "1",
        "--sandbox",
        TEST_SANDBOX.value,
        "--out",
        str(out),
    ]
    for scenario_id in ids:
        command += ["--scenario", scenario_id]
    runner = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    statuses: dict[str, str] = {}
    while time.monotonic() < deadline and not {"done", "running"} <= set(statuses.values()):
        time.sleep(0.1)
        if (out / "summary.json").exists():
            statuses = {e.id: e.status for e in read_summary(out).scenarios}
    os.killpg(runner.pid, signal.SIGKILL)  # the runner and its episode processes
    runner.wait()
    killed = read_summary(out)
    assert not killed.complete
    # the scenario in flight left a trace
    assert "running" in {e.status for e in killed.scenarios}, statuses
    finished = [e.id for e in killed.scenarios if e.status == "done"]
    assert finished, "the first scenario never finished"
    kept = {
        scenario_id: (out / "records" / f"{scenario_id}.npz").stat().st_mtime_ns
        for scenario_id in finished
    }

    summary = run(source, public_suite, out, ids, jobs=1)

    assert summary.complete and [e.status for e in summary.scenarios] == ["done"] * len(ids)
    for scenario_id, mtime in kept.items():
        assert (out / "records" / f"{scenario_id}.npz").stat().st_mtime_ns == mtime
    assert all((out / "records" / f"{scenario_id}.npz").exists() for scenario_id in ids)


def test_a_resumed_run_reuses_the_scores_of_unchanged_records_only(public_suite, tmp_path):
    """A resume takes stored scores (scores.json) instead of re-reading records, and only for
    the records as they were and the profile they were scored with: a record corrupted behind
    the cache's back but looking unchanged keeps its score, one touched since, or any record
    under another profile, is read again (and, corrupt, is reported as ours)."""
    (scenario_id,) = few_scenarios(public_suite, 1)
    source, out = steady(tmp_path), tmp_path / "out"

    def resume(profile: str = DEFAULT_PROFILE):
        return evaluate(
            EvaluationRequest(
                source,
                public_suite,
                out_dir=out,
                scenario_ids=[scenario_id],
                sandbox=TEST_SANDBOX,
                episodes_per_scenario=2,
                profile=profile,
            ),
            **evaluate_args(get_settings()),
        )

    first = resume()
    kept, touched = (
        out / "records" / f"{scenario_id}.npz",
        out / "records" / f"{scenario_id}.ep1.npz",
    )
    assert first.complete and kept.exists() and touched.exists()
    assert (out / "scores.json").exists()
    written = (out / "summary.json").read_bytes()

    def corrupt(record: Path, keep_stamp: bool) -> None:
        stat = record.stat()
        record.write_bytes(b"\0" * stat.st_size)
        if keep_stamp:
            os.utime(record, ns=(stat.st_atime_ns, stat.st_mtime_ns))

    corrupt(kept, keep_stamp=True)
    assert resume() == first
    assert (out / "summary.json").read_bytes() == written

    corrupt(touched, keep_stamp=False)
    (entry,) = resume().scenarios
    assert [e.status for e in entry.episodes] == [ScenarioStatus.done, "evaluator_error"]
    assert "unusable episode record" in entry.episodes[1].error

    # Another profile: the kept record is read again; episode 1, reported as ours, runs again.
    (entry,) = resume("driving-smarts-2022-reference").scenarios
    assert [e.status for e in entry.episodes] == ["evaluator_error", ScenarioStatus.done]


def test_planner_beats_keep_lane_beats_random_on_the_public_set(public_suite, tmp_path):
    results = {
        name: run(example_dir(name), public_suite, tmp_path / name)
        for name in ("planner", "keep_lane", "random")
    }
    n = len(load_suite(public_suite).scenarios)
    for summary in results.values():
        assert summary.complete and summary.uncharged == ()
        assert len(summary.scenarios) == n
    completion = {name: summary.metrics.completion for name, summary in results.items()}
    assert completion["planner"] < completion["keep_lane"] < completion["random"], completion


@pytest.mark.docker
def test_evaluate_in_docker_sandbox(public_suite, tmp_path):
    from arena.config import SandboxKind

    ids = few_scenarios(public_suite, 1)
    summary = evaluate(
        EvaluationRequest(
            steady(tmp_path),
            public_suite,
            out_dir=tmp_path / "out",
            scenario_ids=ids,
            sandbox=SandboxKind.docker,
        ),
        **evaluate_args(get_settings()),
    )
    assert summary.complete and summary.uncharged == ()
    assert summary.scenarios[0].steps > 1


def test_episodes_repeat_reactive_scenarios_with_other_traffic(public_suite, tmp_path):
    """Episode 0 is the single-episode run byte for byte; episode 1 meets other traffic; the
    replay runs once; raising the count on a results folder runs only the new episodes."""
    import numpy as np

    manifest = load_suite(public_suite)
    reactive = next(e.id for e in manifest.scenarios if e.reactive and e.agents == 1)
    replay = next(e.id for e in manifest.scenarios if not e.reactive and e.agents == 1)
    ids = [reactive, replay]
    source = steady(tmp_path)
    once = run(source, public_suite, tmp_path / "once", ids)
    twice = evaluate(
        EvaluationRequest(
            source,
            public_suite,
            out_dir=tmp_path / "twice",
            scenario_ids=ids,
            jobs=2,
            sandbox=TEST_SANDBOX,
            episodes_per_scenario=2,
        ),
        **evaluate_args(get_settings()),
    )

    records = {name: tmp_path / name / "records" for name in ("once", "twice")}
    for scenario_id in ids:
        assert (records["once"] / f"{scenario_id}.npz").read_bytes() == (
            records["twice"] / f"{scenario_id}.npz"
        ).read_bytes()
    assert not (records["twice"] / f"{replay}.ep1.npz").exists()
    with (
        np.load(records["twice"] / f"{reactive}.npz") as first,
        np.load(records["twice"] / f"{reactive}.ep1.npz") as second,
    ):
        assert int(first["seed"]) != int(second["seed"])
        assert not np.array_equal(first["nbr_x"], second["nbr_x"], equal_nan=True)
    entry, replay_entry = twice.scenarios
    assert [e.index for e in entry.episodes] == [0, 1] and replay_entry.episodes is None
    assert entry.episodes[0].agents == once.scenarios[0].agents
    assert twice.episodes_per_scenario == 2

    class Count:
        def started(self, total, done):
            self.total, self.already_done = total, len(done)

        def finished(self, outcome):
            self.ran = (outcome.scenario_id, outcome.episode)

    count = Count()
    again = evaluate(
        EvaluationRequest(
            source,
            public_suite,
            out_dir=tmp_path / "once",
            scenario_ids=ids,
            sandbox=TEST_SANDBOX,
            episodes_per_scenario=2,
        ),
        **evaluate_args(get_settings()),
        progress=count,
    )
    assert (count.total, count.already_done, count.ran) == (3, 2, (reactive, 1))
    assert again == twice


@pytest.mark.docker
def test_warm_and_cold_agents_give_identical_summary_and_records(
    public_suite, tmp_path, monkeypatch
):
    """Forking each episode's agent in a warm sandbox changes who starts it, nothing it does."""
    from arena.config import SandboxKind, get_settings

    ids = few_scenarios(public_suite, 3)
    out = {}
    for warm in (True, False):
        monkeypatch.setenv("ARENA_WARM_AGENTS", str(warm).lower())
        get_settings.cache_clear()
        out[warm] = tmp_path / f"warm-{warm}"
        request = EvaluationRequest(
            example_dir("planner"),
            public_suite,
            out_dir=out[warm],
            scenario_ids=ids,
            sandbox=SandboxKind.docker,
        )
        evaluate(request, **evaluate_args(get_settings()))
    get_settings.cache_clear()
    assert (out[True] / "summary.json").read_bytes() == (out[False] / "summary.json").read_bytes()
    for scenario_id in ids:
        record = f"records/{scenario_id}.npz"
        assert (out[True] / record).read_bytes() == (out[False] / record).read_bytes()
