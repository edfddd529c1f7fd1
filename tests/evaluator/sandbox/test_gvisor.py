"""The stronger tier: the Docker sandbox under gVisor (`ARENA_DOCKER_RUNTIME=runsc`, docs/sandbox.md
"A stronger tier"), where this host's daemon has the runtime registered.

The sandbox tests run again with the runtime set, but for the gaps docs/sandbox.md names (each
deselected here by name, so a gap closed shows as a test to put back): on gVisor's ptrace platform
a warm parent cannot give its forked agents namespaces of their own (the pool runs those
submissions cold), a fork costs several times runc's (the 1 s steps of the fork tests run out),
an agent can kill the sandbox's init (and so only itself), and memory exhausted during start-up
ends the whole sandbox before its reason is read. The process limit, which gVisor holds in its
own kernel rather than in the host's cgroup, is checked with time enough to fork.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from arena.config import SandboxKind, Settings
from evaluator.sandbox import start
from evaluator.sandbox.docker_backend import DockerBackend, docker_client
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.test_placement import expanded, two_cpus
from tests.settings import sandbox_args, with_fields

RUNTIME = "runsc"
REPO = Path(__file__).resolve().parents[3]
MODULES = (
    "test_contract.py",
    "test_hostile.py",
    "test_child_environment.py",
    "test_startup_limits.py",
)
GAPS = (
    "test_contract.py::test_memory_is_capped_for_all_processes_together[docker-warm]",
    "test_contract.py::test_dev_is_not_writable_and_shm_is_bounded[docker-warm]",
    "test_contract.py::test_seccomp_refuses_keyrings_and_new_namespaces[docker-warm]",
    "test_contract.py::test_process_limit_is_per_sandbox_not_per_host_uid[docker]",
    "test_hostile.py::test_hostile_agent_fails_with_its_reason[docker-fork bomb-native]",
    "test_hostile.py::test_hostile_agent_fails_with_its_reason[docker-fork bomb-arrays]",
    "test_hostile.py::test_hostile_agent_fails_with_its_reason[docker-allocating 8 GiB-native]",
    "test_hostile.py::test_hostile_agent_fails_with_its_reason[docker-allocating 8 GiB-arrays]",
    "test_hostile.py::test_killing_its_parent_changes_nothing[docker]",
    "test_child_environment.py::test_no_sandboxed_child_can_find_a_secret[warm agent-docker]",
    "test_startup_limits.py::test_waiting_while_starting_is_not_charged[docker-init-warm]",
    "test_startup_limits.py::test_waiting_while_starting_is_not_charged[docker-reset-warm]",
    "test_startup_limits.py::test_computing_past_the_cpu_limit_is_init_timeout"
    "[docker-init-importing and building the policy-warm]",
    "test_startup_limits.py::test_computing_past_the_cpu_limit_is_init_timeout"
    "[docker-reset-the policy's reset-warm]",
)

pytestmark = [pytest.mark.integration, pytest.mark.docker, pytest.mark.slow]


@pytest.fixture(scope="module")
def gvisor(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    settings = with_fields(
        Settings(),
        storage={"data_dir": tmp_path_factory.mktemp("data")},
        # Forks under gVisor's ptrace platform take seconds of the sandbox's CPU: time to fork.
        sandbox={
            "docker_runtime": RUNTIME,
            "init_timeout_s": 60.0,
            "step_timeout_s": 60.0,
            "step_cpu_s": 30.0,
        },
    )
    reason = DockerBackend().unavailable_reason(settings.sandbox)
    if reason is not None:
        pytest.skip(f"no gVisor here: {reason}")
    return settings


def test_the_agent_runs_on_gvisor(gvisor, tmp_path, labels) -> None:
    submission = agent(tmp_path, gvisor)
    with start(submission, kind=SandboxKind.docker, labels=labels, **sandbox_args(gvisor)) as h:
        h.act(observation())
        selector = [f"{key}={value}" for key, value in labels.items()]
        (container,) = docker_client().containers.list(filters={"label": selector})
        assert container.attrs["HostConfig"]["Runtime"] == RUNTIME


def host_tasks(container) -> list[Path]:
    """Every host thread of ``container`` (gVisor's kernel, its stubs): its cpuset cgroup's,
    read on the host, where placement acts (inside, gVisor's kernel shows CPUs of its own)."""
    pid = container.attrs["State"]["Pid"]
    for line in Path(f"/proc/{pid}/cgroup").read_text().splitlines():
        _, controllers, path = line.split(":", 2)
        if controllers in ("", "cpuset"):  # cgroup v2's one hierarchy, or v1's cpuset
            group = Path("/sys/fs/cgroup", controllers, path.lstrip("/"))
            pids = (group / "cgroup.procs").read_text().split()
            return [task for p in pids for task in Path(f"/proc/{p}/task").iterdir()]
    raise AssertionError(f"no cpuset cgroup for {pid}")


def test_the_agent_runs_on_its_jobs_cpu(gvisor, tmp_path, labels) -> None:
    """Placement under gVisor: every host thread of the sandbox is on the job's CPU, and the
    agent sees one CPU (gVisor's kernel gives its own numbers)."""
    first, last = two_cpus()
    submission = agent(
        tmp_path, gvisor, act="return {k: [len(os.sched_getaffinity(0))] for k in obs}"
    )
    selector = [f"{key}={value}" for key, value in labels.items()]
    for cpus in ((last,), (first,)):
        with start(
            submission, kind=SandboxKind.docker, labels=labels, cpus=cpus, **sandbox_args(gvisor)
        ) as handle:
            handle.reset()
            assert handle.act(observation()) == {"Agent_0": [1.0]}
            (container,) = docker_client().containers.list(filters={"label": selector})
            tasks = host_tasks(container)
            allowed = {
                task.name: next(
                    expanded(line.split(":", 1)[1].strip())
                    for line in (task / "status").read_text().splitlines()
                    if line.startswith("Cpus_allowed_list:")
                )
                for task in tasks
            }
        assert len(allowed) > 1 and all(cpu_list == list(cpus) for cpu_list in allowed.values())


def test_the_process_limit_is_per_sandbox(gvisor, tmp_path) -> None:
    """One sandbox holding 50 processes leaves another free to fork up to its own limit, and
    that one stops there."""
    hog = agent(
        tmp_path / "hog",
        gvisor,
        act="""
        for _ in range(50):
            if os.fork() == 0:
                time.sleep(120)
                os._exit(0)
        return {k: [1.0, 0.0] for k in obs}
        """,
    )
    forker = agent(
        tmp_path / "forker",
        gvisor,
        act="""
        made = 0
        for _ in range(200):
            try:
                pid = os.fork()
            except OSError:
                break
            if pid == 0:
                time.sleep(10)
                os._exit(0)
            made += 1
        return {k: [float(made), 0.0] for k in obs}
        """,
    )
    with start(hog, kind=SandboxKind.docker, **sandbox_args(gvisor)) as held:
        held.act(observation())
        with start(forker, kind=SandboxKind.docker, **sandbox_args(gvisor)) as handle:
            made = handle.act(observation())["Agent_0"][0]
    limit = gvisor.sandbox.agent_pids
    # Its own process and threads take a few of its limit; the other sandbox's 51 take none.
    assert limit - 8 <= made < limit


def test_the_sandbox_tests_hold_under_gvisor(gvisor) -> None:
    # Node ids as pytest writes them: relative to the repository.
    folder = Path(__file__).parent.relative_to(REPO)
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", "docker"]
    command += [str(folder / module) for module in MODULES]
    command += [f"--deselect={folder / gap}" for gap in GAPS]
    env = {**os.environ, "ARENA_DOCKER_RUNTIME": RUNTIME}
    done = subprocess.run(command, env=env, cwd=REPO, capture_output=True, text=True, timeout=3000)
    assert done.returncode == 0, done.stdout[-6000:]
