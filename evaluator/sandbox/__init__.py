"""Running untrusted agents: :func:`start` one in a sandbox and drive it through an AgentHandle.

Backends: ``docker`` (production), ``bubblewrap`` (hosts without Docker) and ``process`` (no
isolation; participants' local runs only). The service runs agents only with a backend that holds
the sandbox contract (docs/sandbox.md) on this machine: :func:`check_service_kind` asks each
backend's ``contract_gap``, which refuses ``process`` always and bubblewrap where no control group
per sandbox can be made. ``auto`` means Docker when a daemon answers, else bubblewrap. Which
backend each kind is: :mod:`evaluator.sandbox.backend_registry`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from arena.config import SandboxKind, SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.errors import SandboxUnavailable
from evaluator.sandbox.backend import SANDBOX_LABEL, ExitStatus, LaunchSpec, Sandbox, Training
from evaluator.sandbox.backend_registry import (
    backend_for,
    check_service_kind,
    client_modules,
    resolve_kind,
)
from evaluator.sandbox.channel import Channel
from evaluator.sandbox.cpu import CpuMeter
from evaluator.sandbox.handle import AgentHandle
from evaluator.sandbox.warm_pool import warm_agents

__all__ = [
    "AgentHandle",
    "check_service_kind",
    "cleanup",
    "client_modules",
    "resolve_kind",
    "start",
    "start_training",
]


def start(
    submission,
    *,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
    limits: CpuLimits | None = None,
    cpus: tuple[int, ...] | None = None,
) -> AgentHandle:
    """Start ``submission`` (a PreparedSubmission) and wait until its Policy is built; the
    sandbox is owned by (labelled with) the resolved ``data_dir``; its acts run under
    ``limits`` (default: ``config``'s), on ``cpus`` (its job's,
    :mod:`evaluator.sandbox.placement`; None: any).

    Raises :class:`~arena.errors.AgentFailed` when the policy fails to import or construct
    within ``init_cpu_s`` of its CPU time (``init_timeout_s`` of wall time as the backstop),
    :class:`~arena.errors.SandboxUnavailable` when the sandbox itself cannot start.
    """
    chosen = backend_for(resolve_kind(kind, config))
    sandbox = chosen.launch(LaunchSpec.of_agent(submission, config, data_dir, labels, cpus=cpus))
    return AgentHandle.started(sandbox, config, submission.interface, limits)


def start_training(
    submission,
    training: Training,
    *,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
) -> Sandbox:
    """Start ``submission``'s ``train.py`` (see :mod:`evaluator.training`) on ``training``'s
    folders, limits and seed (``ARENA_TRAIN_SEED``); it runs until it exits or is killed.
    Raises :class:`~arena.errors.SandboxUnavailable`, also from its ``exit_status`` when it was
    stopped from outside (:class:`BatchSandbox`)."""
    chosen = backend_for(resolve_kind(kind, config))
    spec = LaunchSpec(
        submission=submission.root,
        deps=submission.deps_dir,
        config=config,
        data_dir=data_dir,
        labels=dict(labels or {}),
        training=dataclasses.replace(
            training, dataset=training.dataset.resolve(), output=training.output.resolve()
        ),
    )
    return BatchSandbox(chosen.launch(spec))


class BatchSandbox:
    """A batch run's sandbox (training, an upload's checks, the resolver), whose end its caller
    judges as the team's, except one stopped from outside (``ExitStatus.stopped_by``: the
    Docker daemon told to kill it): ours, raised as :class:`~arena.errors.SandboxUnavailable`,
    so that the job is run again and never charged, whichever batch it was."""

    def __init__(self, sandbox: Sandbox) -> None:
        self._sandbox = sandbox

    def connect(self, deadline: float) -> Channel:
        return self._sandbox.connect(deadline)

    def exit_status(self, timeout: float) -> ExitStatus | None:
        status = self._sandbox.exit_status(timeout)
        if status is not None and status.stopped_by:
            raise SandboxUnavailable(f"the sandbox was {status.describe()}")
        return status

    def kill(self) -> None:
        self._sandbox.kill()

    def logs(self) -> str:
        return self._sandbox.logs()

    def cpu_meter(self) -> CpuMeter | None:
        return self._sandbox.cpu_meter()


def cleanup(config: SandboxSettings, labels: dict[str, str] | None = None) -> int:
    """Remove leftover sandboxes of every backend carrying ``labels`` (default: all of ours),
    and kill this process's leased warm agents carrying them."""
    wanted = {SANDBOX_LABEL: "1", **(labels or {})}
    removed = warm_agents().kill(wanted)
    for kind in (SandboxKind.docker, SandboxKind.bubblewrap):
        removed += backend_for(kind).cleanup(wanted, config)
    return removed
