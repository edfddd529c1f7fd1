"""Which backend runs each sandbox kind, the modules each one loads, and the kind the service and
``auto`` choose (:func:`check_service_kind`, :func:`resolve_kind`)."""

from __future__ import annotations

from arena.config import SandboxKind, SandboxSettings
from arena.errors import SandboxUnavailable
from evaluator.sandbox.backend import Backend

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


def backend_for(kind: SandboxKind) -> Backend:
    """The backend that runs sandboxes of the concrete ``kind``."""
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
    if backend_for(SandboxKind.docker).unavailable_reason(config) is None:
        return SandboxKind.docker
    reason = backend_for(SandboxKind.bubblewrap).unavailable_reason(config)
    if reason is None:
        return SandboxKind.bubblewrap
    raise SandboxUnavailable(f"neither Docker nor bubblewrap can run agents here: {reason}")


def check_service_kind(kind: SandboxKind | str | None, config: SandboxSettings) -> SandboxKind:
    """The backend the service will use: one that holds the sandbox contract here, or
    :class:`SandboxUnavailable` saying why not."""
    resolved = resolve_kind(kind, config)
    gap = backend_for(resolved).contract_gap(config)
    if gap is not None:
        raise SandboxUnavailable(
            f"the service never runs agents with sandbox {resolved.value!r}: {gap}"
        )
    return resolved
