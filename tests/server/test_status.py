"""The status state machine: legal moves pass, everything else (in particular any move
backwards) is refused."""

from __future__ import annotations

import itertools

import pytest

from server.status import (
    RUN_MOVES,
    SUBMISSION_MOVES,
    TRAINING_MOVES,
    IllegalTransition,
    RunStatus,
    SubmissionStatus,
    TrainingStatus,
    advance,
)

# The lifecycle order; a legal move never goes to an earlier stage.
STAGE = {
    SubmissionStatus.received: 0,
    SubmissionStatus.validating: 0,
    SubmissionStatus.queued: 1,
    SubmissionStatus.training: 2,  # offline submissions only
    SubmissionStatus.running: 3,
    SubmissionStatus.scored: 4,
    SubmissionStatus.failed: 4,
    SubmissionStatus.cancelled: 4,
    SubmissionStatus.rejected: 4,
    SubmissionStatus.disqualified: 5,
}
TRAINING_STAGE = {
    TrainingStatus.queued: 0,
    TrainingStatus.training: 1,
    TrainingStatus.trained: 2,
    TrainingStatus.failed: 2,
    TrainingStatus.cancelled: 2,
}


@pytest.mark.parametrize("current,new", list(itertools.product(SubmissionStatus, repeat=2)))
def test_submission_moves(current, new):
    if new in SUBMISSION_MOVES[current]:
        assert advance(current, new, SUBMISSION_MOVES) == new
        assert STAGE[new] >= STAGE[current]
    else:
        with pytest.raises(IllegalTransition):
            advance(current, new, SUBMISSION_MOVES)


@pytest.mark.parametrize("current,new", list(itertools.product(TrainingStatus, repeat=2)))
def test_training_moves(current, new):
    if new in TRAINING_MOVES[current]:
        assert advance(current, new, TRAINING_MOVES) == new
        assert TRAINING_STAGE[new] > TRAINING_STAGE[current]
    else:
        with pytest.raises(IllegalTransition):
            advance(current, new, TRAINING_MOVES)


@pytest.mark.parametrize("current,new", list(itertools.product(RunStatus, repeat=2)))
def test_run_moves(current, new):
    if new in RUN_MOVES[current]:
        assert advance(current, new, RUN_MOVES) == new
    else:
        with pytest.raises(IllegalTransition):
            advance(current, new, RUN_MOVES)


def test_the_main_path_is_legal_and_scored_never_goes_back():
    status = SubmissionStatus.received
    for new in (SubmissionStatus.queued, SubmissionStatus.running, SubmissionStatus.scored):
        status = advance(status, new, SUBMISSION_MOVES)
    for earlier in (
        SubmissionStatus.received,
        SubmissionStatus.queued,
        SubmissionStatus.running,
        SubmissionStatus.failed,
    ):
        with pytest.raises(IllegalTransition):
            advance(status, earlier, SUBMISSION_MOVES)
    assert (
        advance(status, SubmissionStatus.disqualified, SUBMISSION_MOVES)
        == SubmissionStatus.disqualified
    )
