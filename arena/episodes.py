"""Several episodes of one scenario: which scenarios repeat, and with which traffic seeds.

A reactive scenario's background traffic is drawn by SUMO from a seed, so one episode is one draw
among many: an evaluation can run it several times with different traffic and average. Episode 0
is the scenario's own seed, so a one-episode evaluation is exactly the single run it always was;
episode k > 0 derives its seed from the scenario (its id and seed) and k alone, so every
evaluation of every submission sees the same traffic. Non-reactive replays follow their
recording whatever the seed: they always run once.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from dataclasses import dataclass

from arena.suite import ManifestEntry

# SUMO reads --seed as a signed 32-bit integer.
_SEED_RANGE = 2**31


@dataclass(frozen=True, order=True)
class Episode:
    """One episode of one scenario in an evaluation."""

    scenario_id: str
    index: int = 0  # 0: the scenario's own seed

    @property
    def name(self) -> str:
        """Names its record and log files: the scenario id for episode 0 (as before episodes
        existed), ``<scenario id>.ep<k>`` after."""
        return self.scenario_id if self.index == 0 else f"{self.scenario_id}.ep{self.index}"


def episode_count(entry: ManifestEntry, per_reactive_scenario: int) -> int:
    """Episodes of ``entry`` in an evaluation running ``per_reactive_scenario`` per reactive
    scenario."""
    return per_reactive_scenario if entry.reactive else 1


def episodes_of(
    entries: Iterable[ManifestEntry], per_reactive_scenario: int
) -> tuple[Episode, ...]:
    """Every episode of ``entries``, in manifest order, a scenario's episodes together."""
    return tuple(
        Episode(entry.id, index)
        for entry in entries
        for index in range(episode_count(entry, per_reactive_scenario))
    )


def traffic_seed(scenario_id: str, scenario_seed: int, index: int) -> int:
    """The SUMO seed of episode ``index`` of a scenario: its own seed for episode 0, then a hash
    of the scenario and the index (distinct per episode, the same on every machine)."""
    if index == 0:
        return scenario_seed
    digest = hashlib.sha256(f"{scenario_id}\0{scenario_seed}\0{index}".encode()).digest()
    return int.from_bytes(digest[:8], "big") % _SEED_RANGE
