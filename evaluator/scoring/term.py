"""What a metric term is: a pure function of one agent's driven rows (an :class:`AgentTrack`,
arrays of shape ``(n,)`` and neighbours ``(n, K)``) and the profile's constants, returning one
value per row, ``(n,)`` floats. The term modules define terms against this; the registry
(:mod:`evaluator.scoring.registry`) names them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from evaluator.scoring.record import AgentTrack


class TermParameters(Protocol):
    """The constants of a scoring profile (:class:`evaluator.scoring.ScoringProfile`) that terms
    read."""

    @property
    def dt_s(self) -> float: ...  # step length [s]

    @property
    def obs_headway_s(self) -> float: ...  # distance_obs looks this many seconds ahead [s]

    @property
    def obs_half_angle_deg(self) -> float: ...  # ... within this angle of the heading [deg]

    @property
    def obs_decay_per_m(self) -> float: ...  # exp(-decay * d) [1/m]

    @property
    def speeding_tolerance_fraction(self) -> float: ...  # saturates at (1 + f) x limit

    @property
    def wrong_way_angle_deg(self) -> float: ...  # [deg]


Term = Callable[[AgentTrack, TermParameters], np.ndarray]
