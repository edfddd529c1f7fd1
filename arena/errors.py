"""The one error hierarchy of Driving Arena.

Errors are split by whose fault they are. A :class:`ParticipantError` is shown to the team and
never retried: their zip was malformed, their agent crashed or exceeded a limit. An
:class:`InfrastructureError` is ours (Docker daemon gone, sandbox tool missing) and the job is
retried. Library exceptions (docker, subprocess, zipfile) are translated into these at the
boundary where they happen, so callers only ever catch ``ArenaError`` subclasses.

Errors that are neither (an organiser's unusable suite, profile, record or data import; a
service-level refusal, :mod:`server.services.errors`) derive from :class:`ArenaError` directly;
every exception class of the project does, so a command line catches ``ArenaError`` once.
The inside of the sandbox (``agent_runtime/``) imports nothing of ours and keeps its own.
"""

from __future__ import annotations

from arena.outcome import DoneReason


class ArenaError(Exception):
    """Base of every error of ours."""


class ParticipantError(ArenaError):
    """The submission is at fault; shown to its team, not retried."""


class InfrastructureError(ArenaError):
    """Our side failed; the job is retried and never charged to the submission."""


class IntakeError(ParticipantError):
    """A submission zip broke an intake rule.

    ``entry`` names the offending zip entry (or ``"<zip>"`` for the archive as a whole) and
    ``rule`` is the short name of the rule, e.g. ``"zip-slip"`` or ``"max-entries"``.
    """

    def __init__(self, entry: str, rule: str, message: str) -> None:
        super().__init__(f"{entry}: {message} [rule: {rule}]")
        self.entry = entry
        self.rule = rule
        self.message = message


class AgentFailed(ParticipantError):
    """The agent as a whole failed (crashed, timed out, died), not one bad action; the episode
    then ends for every mission vehicle with ``reason``, keeping the steps already driven."""

    def __init__(
        self, reason: DoneReason, detail: str = "", stderr_tail: str = "", cpu_s: float = 0.0
    ) -> None:
        super().__init__(f"{reason}: {detail}" if detail else str(reason))
        self.reason = reason
        self.detail = detail
        self.stderr_tail = stderr_tail
        # The agent's CPU up to the failure [s], from its loading: charged like a finished
        # episode's (an agent failing in __init__ still used the evaluation's budget).
        self.cpu_s = cpu_s


class SandboxUnavailable(InfrastructureError):
    """The requested sandbox cannot run here (no daemon, no image, no bubblewrap)."""


class SuiteError(ArenaError):
    """A scenario suite folder, its manifest or a scenario selection is unusable."""


class RecordError(ArenaError, ValueError):
    """An episode record that does not follow ``docs/records.md`` (ours: never charged)."""


class DatasetError(ArenaError):
    """The training dataset folder is missing or unusable (ours in the service: never charged)."""
