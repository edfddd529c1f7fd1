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


S = SubmissionStatus
R = RunStatus

SUBMISSION_MOVES: dict[SubmissionStatus, frozenset[SubmissionStatus]] = {
    S.received: frozenset({S.queued, S.failed, S.cancelled, S.disqualified}),
    S.validating: frozenset({S.queued, S.rejected, S.failed, S.cancelled, S.disqualified}),
    S.rejected: frozenset(),
    S.queued: frozenset({S.training, S.running, S.failed, S.cancelled, S.disqualified}),
    S.training: frozenset({S.running, S.failed, S.cancelled, S.disqualified}),
    S.running: frozenset({S.scored, S.failed, S.cancelled, S.disqualified}),
    S.scored: frozenset({S.disqualified}),
    S.failed: frozenset({S.scored, S.disqualified}),
    S.cancelled: frozenset({S.disqualified}),
    S.disqualified: frozenset(),
}

RUN_MOVES: dict[RunStatus, frozenset[RunStatus]] = {
    R.queued: frozenset({R.running, R.failed, R.cancelled}),
    R.running: frozenset({R.scored, R.failed, R.cancelled}),
    R.scored: frozenset(),
    R.failed: frozenset(),
    R.cancelled: frozenset(),
}

T_ = TrainingStatus
TRAINING_MOVES: dict[TrainingStatus, frozenset[TrainingStatus]] = {
    T_.queued: frozenset({T_.training, T_.failed, T_.cancelled}),
    T_.training: frozenset({T_.trained, T_.failed, T_.cancelled}),
    T_.trained: frozenset(),
    T_.failed: frozenset(),
    T_.cancelled: frozenset(),
}

ACTIVE_SUBMISSION = frozenset({S.received, S.validating, S.queued, S.training, S.running})
ACTIVE_RUN = frozenset({R.queued, R.running})
ACTIVE_TRAINING = frozenset({T_.queued, T_.training})


class IllegalTransition(ValueError):
    """A status change the state machine forbids (e.g. ``scored -> running``)."""


T = TypeVar("T", SubmissionStatus, RunStatus, TrainingStatus)


def advance(current: T, new: T, moves: dict[T, frozenset[T]]) -> T:
    """``new`` if ``current -> new`` is a legal move; else :class:`IllegalTransition`."""
    if new not in moves[current]:
        raise IllegalTransition(f"cannot move from {current} to {new}")
    return new
