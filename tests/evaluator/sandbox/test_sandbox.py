"""The sandbox as the evaluator uses it: examples run, observations and logs cross intact."""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from arena.config import SandboxKind, Settings
from arena.cpu_limits import CpuLimits
from arena.errors import AgentFailed, SandboxUnavailable
from arena.examples import example_dir
from arena.outcome import DoneReason
from evaluator.sandbox import check_service_kind, cleanup, resolve_kind, start
from submissions.intake import pack_folder, prepare_submission
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.conftest import leftovers, usable
from tests.settings import sandbox_args, with_fields


def packed_example(name: str, tmp: Path, settings: Settings):
    zipped = pack_folder(example_dir(name), tmp / f"{name}.zip")
    return prepare_submission(
        zipped, tmp / name, settings.intake, settings.sandbox, settings.storage.resolved_data_dir
    )


def test_keep_lane_follows_the_lead_vehicle(any_kind, settings, labels, tmp) -> None:
    submission = packed_example("keep_lane", tmp, settings)
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        handle.reset()
        actions = handle.act(observation(("Agent_0", "Agent_1")))
    # The lead is 10 m ahead (centre to centre) at 10 m/s: a 5.5 m gap, below the 8 m minimum.
    assert actions["Agent_0"] == pytest.approx([10.0 + (5.5 - 8.0) / 1.5, 0.0])
    assert set(actions) == {"Agent_0", "Agent_1"}
    assert leftovers(any_kind, labels) == []


def test_random_gives_reachable_target_poses(any_kind, settings, labels, tmp) -> None:
    submission = packed_example("random", tmp, settings)
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        for _ in range(20):
            x, y, heading, dt = handle.act(observation())["Agent_0"]
            assert np.hypot(x - 100.0, y) < 2.8 + 10.0 and dt == 0.1 and abs(heading) < 1e-9


def test_numpy_rasters_cross_intact(any_kind, settings, labels, tmp) -> None:
    act = """
    image = obs['Agent_0']['top_down_rgb']
    image[0, 0, 0] = 7  # writable, like a local array
    return {'Agent_0': [float(image.sum()), *image.shape, float(obs['Agent_0']['dt'])]}
    """
    submission = agent(tmp, settings, act=act)
    obs = observation()
    image = np.arange(64 * 64 * 3, dtype=np.uint8).reshape(64, 64, 3)
    obs["Agent_0"]["top_down_rgb"] = image
    obs["Agent_0"]["dt"] = np.float32(0.1)
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        total, *shape, dt = handle.act(obs)["Agent_0"]
    assert total == float(image.sum()) + 7 - image[0, 0, 0]
    assert shape == [64, 64, 3] and dt == pytest.approx(0.1)


def test_prints_go_to_the_log_not_the_protocol(any_kind, settings, labels, tmp) -> None:
    act = """
    print('thinking about', sorted(obs))
    sys.stdout.flush()
    os.write(1, b'raw fd 1\\n')
    return {k: [3.0, 0.0] for k in obs}
    """
    submission = agent(tmp, settings, act=act, init="print('loaded')")
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        assert handle.act(observation()) == {"Agent_0": [3.0, 0.0]}
        handle.close()
        assert handle.logs() == "loaded\nthinking about ['Agent_0']\nraw fd 1\n"


def test_a_failure_carries_the_stderr_tail(any_kind, settings, labels, tmp) -> None:
    submission = agent(tmp, settings, act="print('about to fail'); 1 / 0")
    with (
        pytest.raises(AgentFailed) as caught,
        start(
            submission,
            kind=any_kind,
            labels=labels,
            **sandbox_args(settings),
        ) as handle,
    ):
        handle.act(observation())
    assert caught.value.reason is DoneReason.agent_error
    assert "ZeroDivisionError" in caught.value.detail
    assert "about to fail" in caught.value.stderr_tail
    with pytest.raises(AgentFailed):
        handle.act(observation())


def test_cleanup_removes_what_a_crashed_worker_left(kind, settings, labels, good_agent) -> None:
    handle = start(
        good_agent,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    )
    assert leftovers(kind, labels) != []
    assert cleanup(settings.sandbox, labels) >= 1
    assert leftovers(kind, labels) == []
    with pytest.raises(AgentFailed) as caught:
        handle.act(observation())
    assert caught.value.reason is DoneReason.agent_exited
    handle.close()


@pytest.mark.slow
def test_cleanup_removes_socket_folders_of_killed_workers(settings, labels, good_agent) -> None:
    from evaluator.sandbox.backend import INSTANCE_LABEL
    from evaluator.sandbox.docker_backend import ORPHAN_SOCKET_DIR_AGE_S, socket_dir_for

    kind = usable(SandboxKind.docker, settings)
    shared = settings.sandbox.sandbox_shared_dir
    stale, fresh = (
        socket_dir_for(uuid.uuid4().hex, shared),
        socket_dir_for(uuid.uuid4().hex, shared),
    )
    for folder in (stale, fresh):
        folder.mkdir()
    old = time.time() - 2 * ORPHAN_SOCKET_DIR_AGE_S
    os.utime(stale, (old, old))
    with start(
        good_agent,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        (container,) = leftovers(kind, labels)
        live = socket_dir_for(container.labels[INSTANCE_LABEL], shared)
        os.utime(live, (old, old))
        cleanup(settings.sandbox, {"driving-arena.test": "nothing-of-ours"})
        assert not stale.exists()
        assert fresh.exists() and live.exists()
        assert handle.act(observation()) is not None
    shutil.rmtree(fresh)
    assert not live.exists()


@pytest.mark.bwrap
def test_cleanup_without_a_docker_daemon_still_cleans_bubblewrap(
    settings, labels, good_agent, monkeypatch: pytest.MonkeyPatch, tmp: Path
) -> None:
    kind = usable(SandboxKind.bubblewrap, settings)
    handle = start(
        good_agent,
        kind=kind,
        labels=labels,
        **sandbox_args(settings),
    )
    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp / 'no-daemon.sock'}")
    assert cleanup(settings.sandbox, labels) >= 1
    assert leftovers(kind, labels) == []
    handle.close()


@pytest.mark.slow
def test_requirements_are_importable_inside(any_kind, settings, labels, tmp) -> None:
    folder = tmp / "src"
    folder.mkdir()
    (folder / "requirements.txt").write_text("six==1.16.0\n")
    (folder / "policy.py").write_text(
        "import six\n\nclass Policy:\n    def act(self, obs):\n"
        "        return {k: [float(six.PY3), 0.0] for k in obs}\n"
    )
    submission = prepare_submission(
        folder,
        tmp / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        assert handle.act(observation()) == {"Agent_0": [1.0, 0.0]}


def test_auto_prefers_docker_and_the_service_refuses_process(settings) -> None:
    from evaluator.sandbox.backend_registry import backend_for

    docker_ok = backend_for(SandboxKind.docker).unavailable_reason(settings.sandbox) is None
    expected = SandboxKind.docker if docker_ok else SandboxKind.bubblewrap
    assert resolve_kind("auto", settings.sandbox) is expected
    assert resolve_kind("process", settings.sandbox) is SandboxKind.process
    with pytest.raises(SandboxUnavailable, match="does not isolate"):
        check_service_kind("process", settings.sandbox)
    assert check_service_kind("auto", settings.sandbox) is expected


@pytest.mark.slow
def test_bubblewrap_agent_is_nobody_on_the_host(settings, labels, tmp) -> None:
    if os.geteuid() != 0:
        pytest.skip("only a root evaluator drops bubblewrap to uid 65534")
    usable(SandboxKind.bubblewrap, settings)
    submission = agent(tmp, settings, act="return {k: [float(os.getuid()), 0.0] for k in obs}")
    with start(
        submission,
        kind="bubblewrap",
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        assert handle.act(observation()) == {"Agent_0": [65534.0, 0.0]}
        pids = leftovers(SandboxKind.bubblewrap, labels)
        assert pids
        for pid in pids:
            status = Path(f"/proc/{pid}/status").read_text()
            real_uid = next(line for line in status.splitlines() if line.startswith("Uid:"))
            assert real_uid.split()[1:] == ["65534"] * 4, (pid, real_uid)


def test_cleanup_of_one_run_spares_another_of_the_same_zip(kind, settings, good_agent) -> None:
    """Two teams uploading identical zips used to share labels (scenario id + zip hash), and
    cancelling one killed the other's sandbox. Labels are per run and attempt now."""
    from evaluator.runner import new_run_key, sandbox_labels

    mine, theirs = new_run_key(), new_run_key()
    first = start(
        good_agent,
        kind=kind,
        labels=sandbox_labels(mine, 1),
        **sandbox_args(settings),
    )
    second = start(
        good_agent,
        kind=kind,
        labels=sandbox_labels(theirs, 1),
        **sandbox_args(settings),
    )
    with first, second:
        assert cleanup(settings.sandbox, sandbox_labels(mine)) >= 1  # every attempt of my run
        assert leftovers(kind, sandbox_labels(mine)) == []
        assert len(leftovers(kind, sandbox_labels(theirs, 1))) >= 1
        assert second.act(observation()) == {"Agent_0": [1.0, 0.0]}
    assert leftovers(kind, sandbox_labels(theirs)) == []


@pytest.mark.slow
def test_nothing_naming_the_scenario_enters_the_sandbox(any_kind, settings, tmp) -> None:
    """The bubblewrap backend put the labels (then the hidden scenario id) in the agent's
    environment; labels are opaque run keys now, and the scenario runner passes nothing else."""
    from evaluator.runner import run_scenario
    from tests.sim.builders import ScenarioSpec, make_scenario

    scenario = make_scenario(tmp / "hidden-scenario-7f3a", ScenarioSpec(max_episode_steps=3))
    scenario_id = json.loads((scenario / "scenario.json").read_text())["id"]
    act = """
    import base64
    seen = repr(sorted(os.environ.items())) + repr(sys.argv) + os.getcwd()
    sys.stderr.write('ENV ' + base64.b64encode(seen.encode()).decode() + ' END\\n')
    return {k: [float('nan')] * 4 for k in obs}
    """
    submission = agent(tmp / "a", settings, act=act)
    outcome = run_scenario(
        submission, scenario, tmp / "records", **sandbox_args(settings), sandbox=any_kind
    )
    encoded = outcome.log.split("ENV ", 1)[1].split(" END", 1)[0]
    inside = base64.b64decode(encoded).decode()
    assert "DRIVING_ARENA" in inside or any_kind is SandboxKind.docker
    assert scenario_id not in inside and "hidden-scenario" not in inside


def test_one_agents_exception_fails_the_whole_agent(any_kind, settings, labels, tmp) -> None:
    """The policy, looping over its agents, raises on Agent_1: the whole agent fails with that
    exception's traceback (every agent of the episode ends with it), as SMARTS 2022's
    evaluation did; which agent the policy held when it raised decides nothing."""
    act = """
    for agent_id, o in obs.items():
        if agent_id == "Agent_1":
            raise ValueError("cannot drive " + o["ego_vehicle_state"]["id"])
    return {agent_id: [1.0, 0.0, 0.0] for agent_id in obs}
    """
    submission = agent(tmp, settings, act=act)
    one = observation()["Agent_0"]
    three = {k: {**one, "ego_vehicle_state": {"id": k}} for k in ("Agent_0", "Agent_1", "Agent_2")}
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as handle:
        handle.reset(list(three))
        with pytest.raises(AgentFailed) as whole:
            handle.act(three)
        assert whole.value.reason is DoneReason.agent_error
        assert "ValueError: cannot drive Agent_1" in whole.value.detail


def test_the_step_limit_counts_cpu_time_not_waiting(any_kind, settings, labels, tmp) -> None:
    """An act that waits 0.6 s without computing is within a 0.4 s CPU limit (a busy worker or
    a slow disk is not the agent's time); one that computes for 0.6 s is not, and is stopped by
    its CPU time, not by the wall-clock backstop (whose message names no CPU)."""
    limits = with_fields(settings, sandbox={"step_cpu_s": 0.4, "step_timeout_s": 120.0})
    act = """
    if obs["Agent_0"]["step_count"] == 0:
        time.sleep(0.6)
    else:
        began = time.process_time()
        while time.process_time() - began < 0.6:
            pass
    return {k: [1.0, 0.0] for k in obs}
    """
    submission = agent(tmp, limits, act=act)
    waiting = observation()
    waiting["Agent_0"]["step_count"] = 0
    with start(
        submission,
        kind=any_kind,
        labels=labels,
        **sandbox_args(limits),
    ) as handle:
        handle.reset()
        assert handle.act(waiting) == {"Agent_0": [1.0, 0.0]}
        with pytest.raises(AgentFailed) as caught:
            handle.act(observation())
        assert caught.value.reason is DoneReason.step_timeout
        assert "s of CPU" in caught.value.detail


def test_an_episode_has_a_cpu_budget(kind, settings, labels, tmp) -> None:
    """Acts of 0.7 s of CPU each, under a 1 s step limit, exceed a 2 s episode budget at the
    third (loading the agent counts too: tests/evaluator/sandbox/test_cpu_from_load.py)."""
    limits = with_fields(
        settings, sandbox={"step_cpu_s": 1.0, "episode_cpu_s": 2.0, "step_timeout_s": 120.0}
    )
    act = """
    began = time.process_time()
    while time.process_time() - began < 0.7:
        pass
    return {k: [1.0, 0.0] for k in obs}
    """
    submission = agent(tmp, limits, act=act)
    with start(
        submission,
        kind=kind,
        labels=labels,
        **sandbox_args(limits),
    ) as handle:
        handle.reset()
        handle.act(observation())
        handle.act(observation())
        assert 1.35 < handle.episode_cpu_s < 2.0
        with pytest.raises(AgentFailed) as caught:
            handle.act(observation())
        assert caught.value.reason is DoneReason.episode_timeout
        assert "CPU this episode" in caught.value.detail


def test_the_runs_own_limits_win_over_the_settings(kind, settings, labels, tmp) -> None:
    """A phase's limits reach the handle as one value: an act of 0.4 s of CPU passes the
    settings' 1 s step limit but not a run's 0.2 s, and what it used before it was stopped is
    counted for the evaluation's budget."""
    settings = with_fields(settings, sandbox={"step_cpu_s": 1.0, "step_timeout_s": 120.0})
    act = """
    began = time.process_time()
    while time.process_time() - began < 0.4:
        pass
    return {k: [1.0, 0.0] for k in obs}
    """
    submission = agent(tmp, settings, act=act)
    tight = CpuLimits(step_s=0.2, episode_s=600.0, evaluation_s=64_800.0)
    with start(
        submission, kind=kind, labels=labels, limits=tight, **sandbox_args(settings)
    ) as handle:
        handle.reset()
        with pytest.raises(AgentFailed) as caught:
            handle.act(observation())
        assert caught.value.reason is DoneReason.step_timeout
        # Stopped while it computes, or on its answer when the poll came too late (a busy host).
        assert "CPU" in caught.value.detail and "0.2 s" in caught.value.detail
        assert handle.episode_cpu_s > 0.2


@pytest.mark.bwrap
def test_the_service_refuses_bubblewrap_that_cannot_cap_each_sandbox(settings) -> None:
    """Where no control group per sandbox can be made (here: the cgroup hierarchies read-only in
    a private mount namespace), bubblewrap would fall back to per-process rlimits; the service
    refuses it and says why."""
    usable(SandboxKind.bubblewrap, settings)
    if os.geteuid() != 0:
        pytest.skip("needs root to make a private mount namespace")
    script = (
        "from arena.config import Settings\n"
        "from evaluator.sandbox import check_service_kind\n"
        "from arena.errors import SandboxUnavailable\n"
        "try:\n"
        "    check_service_kind('bubblewrap', Settings().sandbox)\n"
        "    print('accepted')\n"
        "except SandboxUnavailable as error:\n"
        "    print(error)\n"
    )
    shell = (
        "for m in $(awk '$3 ~ /^cgroup/ {print $2}' /proc/self/mounts); do "
        'mount -o remount,ro,bind "$m"; done; exec python3 -c "$0"'
    )
    done = subprocess.run(
        ["unshare", "--mount", "--propagation", "private", "sh", "-c", shell, script],
        capture_output=True,
        text=True,
        env={**os.environ, "ARENA_DATA_DIR": str(settings.storage.data_dir)},
        timeout=120,
    )
    said = done.stdout.strip()
    assert "cannot enforce per-sandbox limits" in said, (said, done.stderr[-2000:])
    assert "cgroup" in said
