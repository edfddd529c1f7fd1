"""What every sandbox backend provides, so the agent handle never knows which one it drives."""

from __future__ import annotations

import hashlib
import signal
import uuid
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Protocol

import agent_runtime
from agent_runtime import confine
from arena.child_env import child_environment
from arena.config import SandboxKind, SandboxSettings
from evaluator.sandbox.channel import Channel
from evaluator.sandbox.cpu import CpuMeter

# Every sandbox carries this label, so leftovers of a crashed worker are found and removed.
SANDBOX_LABEL = "driving-arena.sandbox"
# And this one, unique to it, so killing one sandbox never touches another with the same labels.
INSTANCE_LABEL = "driving-arena.instance"
# And the data folder of the process that started it (a digest): one service's leftovers are
# removed without touching another's, or a local evaluation's, on the same host.
OWNER_LABEL = "driving-arena.owner"
# Where the runner finds things inside every sandbox.
SUBMISSION_MOUNT = "/submission"
DEPS_MOUNT = "/deps"
# The agent runtime (the package ``agent_runtime``: the program that serves the policy, its warm
# parent and its observation converters) is mounted whole, read-only, at this folder.
RUNTIME_MOUNT = "/opt/arena"
RUNTIME_MAIN = "main.py"
# Track 2 (docs/dataset.md): training runs `train.py` with the dataset read-only and the output
# folder writable; evaluation then mounts that output read-only. Both are named by these variables
# (fixed paths in Docker and bubblewrap, host paths with the process backend).
TRAIN_SCRIPT = "train.py"
DATASET_MOUNT = "/dataset"
MODEL_MOUNT = "/model"
DATASET_ENV = "ARENA_DATASET_DIR"
MODEL_ENV = "ARENA_MODEL_DIR"
# The training's seed (docs/training.md): a phase trains each submission once per seed.
SEED_ENV = "ARENA_TRAIN_SEED"
# One thread for BLAS/OpenMP: the agent has one CPU, and a thread each counts against its pids.
# (No PYTHON* variables: the runner starts with -I, which ignores them; -B keeps bytecode away.)
RUNTIME_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "HOME": "/tmp",
    "TMPDIR": "/tmp",
    "LANG": "C.UTF-8",
}


def runtime_dir() -> Path:
    """The agent runtime's folder on this host, the source of every sandbox's ``/opt/arena``."""
    folder = resources.files(agent_runtime)
    # A sandbox binds a real folder: an installation that left the package zipped cannot serve.
    if not isinstance(folder, Path) or not (folder / RUNTIME_MAIN).is_file():
        raise RuntimeError(f"the agent runtime is not a folder on disk: {folder}")
    return folder


@dataclass(frozen=True)
class Training:
    """A training run instead of an agent: the dataset (read-only), the output folder, and the
    run's own limits (an upload's validation runs this way under the intake's)."""

    dataset: Path
    output: Path
    timeout_s: float
    output_bytes: int  # no single file larger
    gpu: bool = False
    seed: int = 0  # ARENA_TRAIN_SEED
    # More host folders bound read-only, (where the sandbox sees it, host folder): the
    # resolver's pip, package index folders and its proxy's socket (evaluator/resolver.py).
    # Under Docker with a shared folder, those the daemon cannot see are bound as copies
    # (docker_backend.daemon_source); the proxy's is made in the shared folder, a live socket.
    mounts: tuple[tuple[str, Path], ...] = ()

    def env(self, dataset: str, output: str) -> dict[str, str]:
        """The training's variables, with the dataset and output as the sandbox sees them."""
        return {
            DATASET_ENV: dataset,
            MODEL_ENV: output,
            SEED_ENV: str(self.seed),
            "PYTHONUNBUFFERED": "1",
        }


@dataclass(frozen=True)
class LaunchSpec:
    """One agent (or one training run) to start: its folders, labels and the limits it runs
    under."""

    submission: Path
    deps: Path | None
    config: SandboxSettings
    data_dir: Path  # the owner of the sandbox (owner_labels)
    labels: dict[str, str] = field(default_factory=dict)
    observation_format: str = "native"  # agent.yaml's, passed to the runner
    action_space: str = "TargetPose"
    interface: str = ""  # agent.yaml's options as JSON, for formats that describe them (smarts2022)
    # A warm parent forking one agent per episode (evaluator.sandbox.warm) instead of the agent.
    zygote: bool = False
    instance: str = field(default_factory=lambda: uuid.uuid4().hex)
    model: Path | None = None  # a trained output the agent reads (mounted read-only)
    training: Training | None = None  # set: run train.py, not the agent runner
    # The CPUs it runs on, its evaluation job's (evaluator.sandbox.placement); None: any.
    cpus: tuple[int, ...] | None = None

    @classmethod
    def of_agent(
        cls,
        submission,
        config: SandboxSettings,
        data_dir: Path,
        labels: dict[str, str] | None,
        **options,
    ) -> LaunchSpec:
        """The spec of ``submission``'s (a PreparedSubmission) agent, as its ``agent.yaml`` and
        trained output say; ``options``: zygote, cpus."""
        return cls(
            submission=submission.root,
            deps=submission.deps_dir,
            config=config,
            data_dir=data_dir,
            labels=dict(labels or {}),
            observation_format=str(submission.interface.observation_format),
            action_space=str(submission.interface.action_space),
            interface=submission.interface.model_dump_json(),
            model=submission.model_dir,
            **options,
        )

    def python_args(self) -> list[str]:
        """What the sandbox's python3 runs: the agent runner, or the submission's train.py."""
        if self.training is not None:
            # Not -I: PYTHONPATH is how train.py finds its installed requirements.
            return ["-B", "-s", f"{SUBMISSION_MOUNT}/{TRAIN_SCRIPT}"]
        return self.runner_args()

    def sandbox_env(
        self,
        path: str,
        *,
        deps: str = DEPS_MOUNT,
        dataset: str = DATASET_MOUNT,
        model: str = MODEL_MOUNT,
    ) -> dict[str, str]:
        """The whole environment of the sandbox's process (:func:`child_environment`: nothing
        of the host's, no secret), with ``PATH`` and the folders as the sandbox sees them
        (the fixed mount points but with the process backend)."""
        env = dict(RUNTIME_ENV, PATH=path)
        if self.training is not None:
            env |= self.training.env(dataset, model)
            if self.deps:
                env["PYTHONPATH"] = deps
        elif self.model is not None:
            env[MODEL_ENV] = model
        return child_environment(env)

    def seccomp_program(self) -> bytes:
        """The sandbox's seccomp filter (``agent_runtime/confine.py``): the agents' own, or for
        a warm parent the same but for what it needs to make each episode new (its children
        install the agents' filter before any participant code)."""
        return confine.program(warm_parent=self.zygote)

    def seccomp_profile(self) -> str:
        """The same filter as a Docker seccomp profile."""
        return confine.docker_profile(warm_parent=self.zygote)

    def cpu_seconds(self) -> float:
        """CPU time the sandbox may burn where no cgroup caps its share (bubblewrap): the
        start-up's CPU limit plus the run's wall time on its CPUs (an episode's on one)."""
        config = self.config
        if self.training is not None:
            return self.training.timeout_s * config.agent_cpus + config.init_cpu_s
        return config.init_cpu_s + config.episode_timeout_s

    @property
    def all_labels(self) -> dict[str, str]:
        return {
            **self.labels,
            SANDBOX_LABEL: "1",
            INSTANCE_LABEL: self.instance,
            **owner_labels(self.data_dir),
        }

    @property
    def instance_labels(self) -> dict[str, str]:
        return {INSTANCE_LABEL: self.instance}

    def runner_args(self) -> list[str]:
        deps = ["--deps", DEPS_MOUNT] if self.deps else []
        return [
            "-I",
            "-B",
            f"{RUNTIME_MOUNT}/{RUNTIME_MAIN}",
            "--submission",
            SUBMISSION_MOUNT,
            *deps,
            *self.format_args(),
        ]

    def format_args(self) -> list[str]:
        """The runner's options beyond its folders: the observation format, warm mode."""
        zygote = (
            ["--zygote", "--scratch-bytes", str(self.config.agent_tmp_bytes)] if self.zygote else []
        )
        if self.observation_format == "native":
            return zygote
        return [
            "--observation-format",
            self.observation_format,
            "--action-space",
            self.action_space,
            *(["--interface", self.interface] if self.interface else []),
            *zygote,
        ]


@dataclass(frozen=True)
class ExitStatus:
    code: int | None
    oom_killed: bool = False
    # Who stopped the sandbox from outside, as facts of ours say (the Docker daemon's events:
    # nothing inside a container can make the daemon kill it); "" when nothing we can see did.
    stopped_by: str = ""

    def describe(self) -> str:
        if self.stopped_by:
            return f"stopped from outside by {self.stopped_by}"
        if self.oom_killed:
            return "killed for exceeding its memory limit"
        if self.code is None:
            return "ended for an unknown reason"
        if self.code < 0:
            return f"killed by {signal_name(-self.code)}"
        if self.code > 128:
            return f"exited with status {self.code} ({signal_name(self.code - 128)})"
        return f"exited with status {self.code}"


# Signals a participant can act on when told what they mean.
SIGNAL_MEANINGS = {
    signal.SIGXCPU: "the CPU time limit of one episode was used up",
    signal.SIGSEGV: "a segmentation fault",
}


def signal_name(number: int) -> str:
    try:
        sig = signal.Signals(number)
    except ValueError:
        return f"signal {number}"
    meaning = SIGNAL_MEANINGS.get(sig)
    return f"{sig.name}: {meaning}" if meaning else sig.name


class Sandbox(Protocol):
    """One running agent."""

    def connect(self, deadline: float) -> Channel:
        """The protocol channel, once the runner is reachable (``deadline``: monotonic time)."""

    def exit_status(self, timeout: float) -> ExitStatus | None:
        """How the agent ended, or None if it is still running after ``timeout`` seconds."""

    def kill(self) -> None:
        """Stop it and release everything it holds; safe to call twice."""

    def logs(self) -> str:
        """The last ``agent_log_tail_bytes`` of its stdout/stderr."""

    def cpu_meter(self) -> CpuMeter | None:
        """How to read the CPU time it has used from the host (None: no way here)."""


class Backend(Protocol):
    kind: SandboxKind

    def unavailable_reason(self, config: SandboxSettings) -> str | None:
        """Why this backend cannot run here, or None when it can."""

    def contract_gap(self, config: SandboxSettings) -> str | None:
        """Why it does not hold the sandbox contract here (docs/sandbox.md), so the service
        refuses it, or None when it does (the one answer to what the service runs agents with)."""

    def launch(self, spec: LaunchSpec) -> Sandbox: ...

    def cleanup(self, labels: dict[str, str], config: SandboxSettings) -> int:
        """Kill and remove every sandbox carrying all ``labels``; returns how many."""


def owner_labels(data_dir: Path) -> dict[str, str]:
    """The label every sandbox started for the service (or run) whose data folder is the
    resolved ``data_dir`` carries: that folder's digest."""
    digest = hashlib.sha256(str(data_dir).encode()).hexdigest()[:16]
    return {OWNER_LABEL: digest}
