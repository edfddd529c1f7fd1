"""What a team sees of the timing of its evaluation in a hidden phase: nothing finer than a unit.

An agent can make its time depend on what it sees (sleep, burn CPU, fail after a while): read
finely, any clock of a hidden run (progress episode by episode, a live duration, the moment it
finished, the CPU it used) would carry what the agent saw of hidden scenarios to its team. So
while the phase is hidden, its team sees:

- the state, and progress in quarters of the run whatever the suite's size (never an episode at
  a time: a run too small for a quarter to span several episodes shows none until its end);
- no duration while the run is under way; once it ended, the duration rounded up to
  :data:`UNIT_S`, and no finish time (the start and the duration are what there is);
- the CPU its agent used rounded up to :data:`UNIT_S` (shown only once the run ended).

Organisers see the exact figures (``arena admin``). A phase released after it closed shows
everything (``phases.team_sees_everything``).
"""

from __future__ import annotations

import math

from server.schemas import Progress

UNIT_S = 600.0  # ten minutes
PROGRESS_STEPS = 4
MIN_EPISODES_PER_STEP = 2


def coarse_s(seconds: float) -> float:
    """``seconds`` rounded up to a whole unit (at least one)."""
    return max(1, math.ceil(seconds / UNIT_S - 1e-9)) * UNIT_S


def coarse_cpu_s(seconds: float) -> float:
    """CPU ``seconds`` rounded up to a whole unit (none stays none)."""
    return math.ceil(seconds / UNIT_S - 1e-9) * UNIT_S


def quarter_progress(done: int, total: int, seeds: int) -> Progress:
    """``done`` of ``total`` episodes, told in quarters of the run. A quarter must span
    :data:`MIN_EPISODES_PER_STEP` episodes or more: on a smaller run a quarter would be an
    episode, and its step would time that episode, so such a run shows no step until its end."""
    coarse_enough = total >= PROGRESS_STEPS * MIN_EPISODES_PER_STEP
    quarters = done * PROGRESS_STEPS // total if coarse_enough else 0
    return Progress(done=quarters, total=PROGRESS_STEPS, seeds=seeds, unit="quarters")
