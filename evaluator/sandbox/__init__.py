"""Running untrusted agents: :func:`start` one in a sandbox and drive it through an AgentHandle.

Backends: ``docker`` (production), ``bubblewrap`` (hosts without Docker) and ``process`` (no
isolation; participants' local runs only). The service runs agents only with a backend that holds
the sandbox contract (docs/sandbox.md) on this machine: :func:`check_service_kind` asks each
backend's ``contract_gap``, which refuses ``process`` always and bubblewrap where no control group
per sandbox can be made. ``auto`` means Docker when a daemon answers, else bubblewrap.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from arena.config import SandboxKind, SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.errors import SandboxUnavailable
from evaluator.sandbox.backend import SANDBOX_LABEL, Backend, LaunchSpec, Sandbox, Training
from evaluator.sandbox.handle import AgentHandle

__all__ = [
    "AgentHandle",
    "backend",
    "check_service_kind",
    "cleanup",
    "client_modules",
    "resolve_kind",
    "start",
    "start_training",
]

# What starting an agent with each backend imports (its module and client library): a warm
# parent process imports them once instead of every episode's process.
_CLIENT_MODULES: dict[SandboxKind, tuple[str, ...]] = {
    SandboxKind.docker: ("evaluator.sandbox.docker_backend", "docker", "docker.types"),
    SandboxKind.bubblewrap: ("evaluator.sandbox.bwrap_backend",),
    SandboxKind.process: ("evaluator.sandbox.process_backend",),
}


def client_modules(kind: SandboxKind | str | None) -> tuple[str, ...]:
    """The modules :func:`start` imports for ``kind``; every backend's when the kind is not yet
    resolved (None or ``auto``), since resolving may probe the Docker daemon."""
    if kind is None or SandboxKind(kind) is SandboxKind.auto:
        return tuple(m for modules in _CLIENT_MODULES.values() for m in modules)
    return _CLIENT_MODULES[SandboxKind(kind)]


def backend(kind: SandboxKind) -> Backend:
    if kind is SandboxKind.docker:
        # deferred: a backend's client modules load only when it is chosen
        from evaluator.sandbox.docker_backend import DockerBackend

        return DockerBackend()
    if kind is SandboxKind.bubblewrap:
        # deferred: a backend's client modules load only when it is chosen
        from evaluator.sandbox.bwrap_backend import BubblewrapBackend

        return BubblewrapBackend()
    if kind is SandboxKind.process:
        # deferred: a backend's client modules load only when it is chosen
        from evaluator.sandbox.process_backend import ProcessBackend

        return ProcessBackend()
    raise ValueError(f"{kind} is not a concrete sandbox kind")


def resolve_kind(kind: SandboxKind | str | None, config: SandboxSettings) -> SandboxKind:
    """The concrete backend for ``kind`` (None: the setting); ``auto`` prefers Docker."""
    kind = SandboxKind(kind or config.kind)
    if kind is not SandboxKind.auto:
        return kind
    if backend(SandboxKind.docker).unavailable_reason(config) is None:
        return SandboxKind.docker
    reason = backend(SandboxKind.bubblewrap).unavailable_reason(config)
    if reason is None:
        return SandboxKind.bubblewrap
    raise SandboxUnavailable(f"neither Docker nor bubblewrap can run agents here: {reason}")


def check_service_kind(kind: SandboxKind | str | None, config: SandboxSettings) -> SandboxKind:
    """The backend the service will use: one that holds the sandbox contract here, or
    :class:`SandboxUnavailable` saying why not."""
    resolved = resolve_kind(kind, config)
    gap = backend(resolved).contract_gap(config)
    if gap is not None:
        raise SandboxUnavailable(
            f"the service never runs agents with sandbox {resolved.value!r}: {gap}"
        )
    return resolved


def start(
    submission,
    *,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
    limits: CpuLimits | None = None,
) -> AgentHandle:
    """Start ``submission`` (a PreparedSubmission) and wait until its Policy is built; the
    sandbox is owned by (labelled with) the resolved ``data_dir``; its acts run under
    ``limits`` (default: ``config``'s).

    Raises :class:`~arena.errors.AgentFailed` when the policy fails to import or construct
    in ``init_timeout_s``, :class:`~arena.errors.SandboxUnavailable` when the sandbox itself
    cannot start.
    """
    chosen = backend(resolve_kind(kind, config))
    sandbox = chosen.launch(LaunchSpec.of_agent(submission, config, data_dir, labels))
    handle = AgentHandle(sandbox, config, submission.interface, limits)
    try:
        handle.handshake()
    except BaseException:
        handle.close()
        raise
    return handle


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
    Raises :class:`~arena.errors.SandboxUnavailable`."""
    chosen = backend(resolve_kind(kind, config))
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
    return chosen.launch(spec)


def cleanup(config: SandboxSettings, labels: dict[str, str] | None = None) -> int:
    """Remove leftover sandboxes of every backend carrying ``labels`` (default: all of ours),
    and kill this process's leased warm agents carrying them."""
    # deferred: the warm pool imports this package (evaluator.sandbox.warm uses backend())
    from evaluator.sandbox.warm_pool import warm_agents

    wanted = {SANDBOX_LABEL: "1", **(labels or {})}
    removed = warm_agents().kill(wanted)
    for kind in (SandboxKind.docker, SandboxKind.bubblewrap):
        removed += backend(kind).cleanup(wanted, config)
    return removed
