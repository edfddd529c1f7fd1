"""Submission and evaluation-run status: an enum state machine that never moves backwards.

A submission goes ``validating -> queued -> running -> scored | failed``: an upload is validated
by a job (in the sandbox) and ends ``rejected``, naming the rule, when it breaks one (it does not
count towards the quota). An offline (Track 2) one
trains first: ``queued -> training -> running``. It can be ``cancelled``
before it finishes and ``disqualified`` at any time. A later evaluation attempt (``arena admin
rerun``) that scores turns a ``failed`` submission ``scored``; a ``scored`` one never becomes
``failed`` again (a failed re-run leaves the earlier score standing).
"""

from __future__ import annotations

from enum import StrEnum
from typing import TypeVar

from arena.errors import ArenaError


class SubmissionStatus(StrEnum):
    received = "received"  # before validation jobs: uploads checked in the request
    validating = "validating"
    rejected = "rejected"
    queued = "queued"
    training = "training"
    running = "running"
    scored = "scored"
    failed = "failed"
    cancelled = "cancelled"
    disqualified = "disqualified"


class TrainingStatus(StrEnum):
    queued = "queued"
    training = "training"
    trained = "trained"
    failed = "failed"
    cancelled = "cancelled"


class RunStatus(StrEnum):
    queued = "queued"
    running = "running"
    scored = "scored"
    failed = "failed"
    cancelled = "cancelled"


SUBMISSION_MOVES: dict[SubmissionStatus, frozenset[SubmissionStatus]] = {
    SubmissionStatus.received: frozenset(
        {
            SubmissionStatus.queued,
            SubmissionStatus.failed,
            SubmissionStatus.cancelled,
            SubmissionStatus.disqualified,
        }
    ),
    SubmissionStatus.validating: frozenset(
        {
            SubmissionStatus.queued,
            SubmissionStatus.rejected,
            SubmissionStatus.failed,
            SubmissionStatus.cancelled,
            SubmissionStatus.disqualified,
        }
    ),
    SubmissionStatus.rejected: frozenset(),
    SubmissionStatus.queued: frozenset(
        {
            SubmissionStatus.training,
            SubmissionStatus.running,
            SubmissionStatus.failed,
            SubmissionStatus.cancelled,
            SubmissionStatus.disqualified,
        }
    ),
    SubmissionStatus.training: frozenset(
        {
            SubmissionStatus.running,
            SubmissionStatus.failed,
            SubmissionStatus.cancelled,
            SubmissionStatus.disqualified,
        }
    ),
    SubmissionStatus.running: frozenset(
        {
            SubmissionStatus.scored,
            SubmissionStatus.failed,
            SubmissionStatus.cancelled,
            SubmissionStatus.disqualified,
        }
    ),
    SubmissionStatus.scored: frozenset({SubmissionStatus.disqualified}),
    SubmissionStatus.failed: frozenset({SubmissionStatus.scored, SubmissionStatus.disqualified}),
    SubmissionStatus.cancelled: frozenset({SubmissionStatus.disqualified}),
    SubmissionStatus.disqualified: frozenset(),
}

RUN_MOVES: dict[RunStatus, frozenset[RunStatus]] = {
    RunStatus.queued: frozenset({RunStatus.running, RunStatus.failed, RunStatus.cancelled}),
    RunStatus.running: frozenset({RunStatus.scored, RunStatus.failed, RunStatus.cancelled}),
    RunStatus.scored: frozenset(),
    RunStatus.failed: frozenset(),
    RunStatus.cancelled: frozenset(),
}

TRAINING_MOVES: dict[TrainingStatus, frozenset[TrainingStatus]] = {
    TrainingStatus.queued: frozenset(
        {TrainingStatus.training, TrainingStatus.failed, TrainingStatus.cancelled}
    ),
    TrainingStatus.training: frozenset(
        {TrainingStatus.trained, TrainingStatus.failed, TrainingStatus.cancelled}
    ),
    TrainingStatus.trained: frozenset(),
    TrainingStatus.failed: frozenset(),
    TrainingStatus.cancelled: frozenset(),
}

ACTIVE_SUBMISSION = frozenset(
    {
        SubmissionStatus.received,
        SubmissionStatus.validating,
        SubmissionStatus.queued,
        SubmissionStatus.training,
        SubmissionStatus.running,
    }
)
ACTIVE_RUN = frozenset({RunStatus.queued, RunStatus.running})
ACTIVE_TRAINING = frozenset({TrainingStatus.queued, TrainingStatus.training})


class IllegalTransition(ArenaError, ValueError):
    """A status change the state machine forbids (e.g. ``scored -> running``)."""


StatusT = TypeVar("StatusT", SubmissionStatus, RunStatus, TrainingStatus)


def advance(current: StatusT, new: StatusT, moves: dict[StatusT, frozenset[StatusT]]) -> StatusT:
    """``new`` if ``current -> new`` is a legal move; else :class:`IllegalTransition`."""
    if new not in moves[current]:
        raise IllegalTransition(f"cannot move from {current} to {new}")
    return new
