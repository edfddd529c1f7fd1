"""Episode workers: a process running episodes one after another records each one as a process of
its own would, whatever ran in it before, and fails as one would."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from arena.episodes import traffic_seed
from arena.outcome import DoneReason
from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.episode_workers import EpisodeWorkers, InputsKept
from sim.inputs import PackedInputsCache
from sim.interface import AgentInterface
from tests.sim.agents import ScriptedAgent, crashing_agent, hanging_agent

# A lane-following agent: every episode drives through the scenario's traffic to its end.
IN_LANE = AgentInterface(action_space="LaneWithContinuousSpeed")
MERGE, CRUISE = "p009_merge_2lane_low", "p016_cruise_2lane_low"
BUBBLE = "p029_replay_i80_bubble"
REPO = Path(__file__).resolve().parents[2]


def keep_lane_at_8(obs: dict) -> list[float]:
    return [8.0, 0.0]


class _PidAgent(ScriptedAgent):
    def logs(self) -> str:
        return f"pid {os.getpid()}"


def pid_agent() -> ScriptedAgent:
    """Drives in its lane; its log names the process that ran its episode."""
    return _PidAgent(keep_lane_at_8)


@dataclass(frozen=True)
class SocketGreeter:
    """A factory holding a socket, as a forked agent's does: says hello on it when called."""

    end: socket.socket

    def __call__(self) -> ScriptedAgent:
        self.end.send(b"hello")
        return pid_agent()


def run(workers: EpisodeWorkers, tmp_path, scenario_id: str, index: int, factory=pid_agent):
    folder = SHIPPED_PUBLIC_DIR / scenario_id
    scenario = load_scenario(folder)
    record = tmp_path / f"{scenario_id}.ep{index}.npz"
    seed = traffic_seed(scenario.id, scenario.seed, index)
    result = workers.run_episode(folder, factory, IN_LANE, record_path=record, seed=seed)
    return result, record


@pytest.mark.slow
def test_an_episode_records_the_same_bytes_alone_and_after_others(tmp_path):
    """Episode 2 of a scenario in a fresh worker and in one that ran other episodes of it (its
    inputs kept) and of another scenario first: the same record, byte for byte."""
    after, alone = EpisodeWorkers(), EpisodeWorkers()
    try:
        results = [
            run(after, tmp_path / "after", scenario_id, index)[0]
            for scenario_id, index in [(MERGE, 0), (CRUISE, 0), (MERGE, 1)]
        ]
        shared, shared_record = run(after, tmp_path / "after", MERGE, 2)
        own, own_record = run(alone, tmp_path / "alone", MERGE, 2)
    finally:
        after.close()
        alone.close()
    assert len({r.extra["agent_log"] for r in [*results, shared]}) == 1  # one process
    assert own.extra["agent_log"] != shared.extra["agent_log"]
    assert shared.steps > 100 and shared.simulator_error is None
    assert shared_record.read_bytes() == own_record.read_bytes()
    assert shared.agents == own.agents


@pytest.mark.slow
def test_a_bubble_replay_records_the_same_bytes_alone_and_after_itself(tmp_path):
    """A replay's recording, worked out once per worker, replays anew in every episode."""
    after, alone = EpisodeWorkers(), EpisodeWorkers()
    try:
        run(after, tmp_path / "after", BUBBLE, 0)
        shared, shared_record = run(after, tmp_path / "after", BUBBLE, 1)
        _, own_record = run(alone, tmp_path / "alone", BUBBLE, 1)
    finally:
        after.close()
        alone.close()
    assert shared.steps > 100 and shared.simulator_error is None
    assert shared_record.read_bytes() == own_record.read_bytes()


def test_a_crash_is_a_simulator_error_and_the_next_episode_gets_a_new_process(tmp_path):
    workers = EpisodeWorkers()
    try:
        first, _ = run(workers, tmp_path, CRUISE, 0)
        crashed, _ = run(workers, tmp_path, CRUISE, 1, crashing_agent)
        after, _ = run(workers, tmp_path, CRUISE, 0)
    finally:
        workers.close()
    assert crashed.simulator_error and "exit code -11" in crashed.simulator_error
    assert [a.reason for a in crashed.agents] == [DoneReason.simulator_error]
    assert after.simulator_error is None
    assert after.extra["agent_log"] != first.extra["agent_log"]


@pytest.mark.slow
def test_a_hung_episode_is_killed_at_the_hard_timeout(tmp_path):
    workers = EpisodeWorkers()
    folder = SHIPPED_PUBLIC_DIR / CRUISE
    try:
        result = workers.run_episode(
            folder, hanging_agent, IN_LANE, record_path=tmp_path / "r.npz", timeout_s=3
        )
    finally:
        workers.close()
    assert result.simulator_error and "exceeded 3 s" in result.simulator_error


def test_a_factory_s_sockets_reach_the_episode_and_close_with_it(tmp_path):
    ours, theirs = socket.socketpair()
    workers = EpisodeWorkers()
    try:
        result, _ = run(workers, tmp_path, CRUISE, 0, SocketGreeter(theirs))
        theirs.close()  # the worker's copy is the only one left: closed after the episode
        ours.settimeout(10)
        assert ours.recv(16) == b"hello"
        assert ours.recv(16) == b""
    finally:
        workers.close()
        ours.close()
    assert result.simulator_error is None


def test_the_workers_of_an_evaluation_end_with_it(tmp_path):
    """Evaluations under way share the workers (one ending beside another keeps them); when
    the last one ends, its idle worker ends at once, not after the idle time."""
    workers = EpisodeWorkers()
    try:
        with workers.serving():
            with workers.serving():
                first, _ = run(workers, tmp_path, CRUISE, 0)
            second, _ = run(workers, tmp_path, CRUISE, 1)
            pid = int(first.extra["agent_log"].removeprefix("pid "))
            assert second.extra["agent_log"] == first.extra["agent_log"]
            assert Path(f"/proc/{pid}").exists()
        assert not Path(f"/proc/{pid}").exists()
    finally:
        workers.close()


def test_kept_inputs_are_read_once_per_content_and_bounded(tmp_path):
    cache = PackedInputsCache()
    merge_key, merge_fd = cache.open_keyed(SHIPPED_PUBLIC_DIR / MERGE)
    kept = InputsKept(limit=1)
    first = kept.take(merge_key, merge_fd)
    again_fd = cache.open_keyed(SHIPPED_PUBLIC_DIR / MERGE)[1]
    assert kept.take(merge_key, again_fd) is first
    with pytest.raises(OSError):
        os.fstat(again_fd)  # closed although not read
    cruise_key, cruise_fd = cache.open_keyed(SHIPPED_PUBLIC_DIR / CRUISE)
    kept.take(cruise_key, cruise_fd)
    assert cruise_key in kept and merge_key not in kept  # past the limit: the newest only


def test_relative_paths_are_the_caller_s_at_each_episode(tmp_path, monkeypatch):
    workers = EpisodeWorkers()
    folder = SHIPPED_PUBLIC_DIR / CRUISE
    try:
        for name in ("first", "second"):
            (tmp_path / name).mkdir()
            monkeypatch.chdir(tmp_path / name)
            workers.run_episode(folder, pid_agent, IN_LANE, record_path="records/r.npz")
    finally:
        workers.close()
    assert (tmp_path / "first/records/r.npz").is_file()
    assert (tmp_path / "second/records/r.npz").is_file()


EXITS_AFTER_AN_EPISODE = f"""
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.episode_workers import episode_workers
from tests.sim.test_episode_workers import IN_LANE, pid_agent

result = episode_workers().run_episode(SHIPPED_PUBLIC_DIR / {CRUISE!r}, pid_agent, IN_LANE,
                                       record_path={{record!r}})
print(result.extra["agent_log"])
"""


def test_a_process_with_an_idle_worker_exits(tmp_path):
    """At exit its idle worker ends, whichever exit handler comes first (multiprocessing's
    waits for every child that is not daemonic), and no simulator process outlives it (as
    `arena evaluate` exits)."""
    script = EXITS_AFTER_AN_EPISODE.format(record=str(tmp_path / "r.npz"))
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, timeout=120, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "r.npz").is_file()
    worker = int(done.stdout.split()[-1])
    assert not Path(f"/proc/{worker}").exists()
