"""SMARTS's per-step events (``smarts.core.events``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple


class Collision(NamedTuple):
    collidee_id: str
    collidee_owner_id: str = ""  # the agent driving the other vehicle; "" for traffic


class Events(NamedTuple):
    collisions: Sequence[Collision]
    off_road: bool
    off_route: bool
    on_shoulder: bool
    wrong_way: bool
    not_moving: bool
    reached_goal: bool
    reached_max_episode_steps: bool
    agents_alive_done: bool = False
