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

S = SubmissionStatus
# The lifecycle order; a legal move never goes to an earlier stage.
STAGE = {
    S.received: 0,
    S.validating: 0,
    S.queued: 1,
    S.training: 2,  # offline submissions only
    S.running: 3,
    S.scored: 4,
    S.failed: 4,
    S.cancelled: 4,
    S.rejected: 4,
    S.disqualified: 5,
}
T = TrainingStatus
TRAINING_STAGE = {T.queued: 0, T.training: 1, T.trained: 2, T.failed: 2, T.cancelled: 2}


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
    status = S.received
    for new in (S.queued, S.running, S.scored):
        status = advance(status, new, SUBMISSION_MOVES)
    for earlier in (S.received, S.queued, S.running, S.failed):
        with pytest.raises(IllegalTransition):
            advance(status, earlier, SUBMISSION_MOVES)
    assert advance(status, S.disqualified, SUBMISSION_MOVES) == S.disqualified
