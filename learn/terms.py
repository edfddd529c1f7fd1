"""The scoring profile's humanness and rules terms of one agent-step, for ``info``.

The evaluator computes each term over a whole episode record (``evaluator.scoring.terms``); here
the same functions run on the last rows the simulator recorded for the agent (three: jerk looks
two steps back), and the value of the newest row is the step's term.
"""

from __future__ import annotations

import numpy as np

from arena.record_format import STEP_FLOATS
from evaluator.scoring.profile import ScoringProfile
from evaluator.scoring.record import AgentTrack
from evaluator.scoring.registry import get_term
from sim.record import RecordRow

_ROWS_NEEDED = 3


def track_of(rows: list[RecordRow]) -> AgentTrack:
    """An :class:`AgentTrack` of ``rows`` (oldest first), neighbours padded to the widest row."""
    k = max([1] + [len(r.neighbours) for r in rows])
    nbr_valid = np.zeros((len(rows), k), bool)
    nbr_x = np.full((len(rows), k), np.nan)
    nbr_y = np.full((len(rows), k), np.nan)
    for i, row in enumerate(rows):
        m = len(row.neighbours)
        nbr_valid[i, :m] = True
        nbr_x[i, :m] = row.neighbours.x
        nbr_y[i, :m] = row.neighbours.y
    # One array for every scalar column: this runs on every env step.
    table = np.array([[getattr(r, name) for name in STEP_FLOATS] for r in rows], float).T
    return AgentTrack(
        **dict(zip(STEP_FLOATS, table, strict=True)),
        in_junction=np.array([r.in_junction for r in rows], bool),
        nbr_valid=nbr_valid,
        nbr_x=nbr_x,
        nbr_y=nbr_y,
    )


def step_terms(rows: list[RecordRow], profile: ScoringProfile) -> dict[str, float]:
    """Every humanness and rules term of the newest row of ``rows`` (an agent's record so far);
    empty before the agent has driven."""
    if not rows:
        return {}
    track = track_of(rows[-_ROWS_NEEDED:])
    names = (*profile.humanness_terms, *profile.rules_terms)
    return {name: float(get_term(name)(track, profile)[-1]) for name in names}
