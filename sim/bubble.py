"""Replay with a reactive bubble: recorded vehicles handed to SUMO when a mission vehicle nears."""

from __future__ import annotations

import math

from sim.playback import ReplayTable
from sim.road import RoadNetwork
from sim.road.waypoints import route_ahead
from sim.traffic import SumoTraffic


class ReactiveBubble:
    """Recorded vehicles live in SUMO (so that the vehicles already handed over react to them),
    moved to their recorded states every step until a mission vehicle comes within ``radius``
    [m]; from then on SUMO drives them for the rest of the episode.

    An episode may outlive its recording (an ego slower than the recorded one): a vehicle still
    replayed leaves SUMO after its last recorded frame, one handed over drives on; past the last
    frame of the whole recording only the handed-over vehicles are left.
    """

    def __init__(self, table: ReplayTable, radius: float, road: RoadNetwork) -> None:
        self.table = table
        self.radius = radius
        self.road = road
        self._in_sumo: set[str] = set()  # replayed (not yet handed over) vehicles in SUMO

    def update(self, traffic: SumoTraffic, step: int, egos: list[tuple[float, float]]) -> None:
        """Place every replayed vehicle for ``step``; hand over those within reach of ``egos``
        (centres [m])."""
        table = self.table
        present = table.present(step)
        present_ids = {table.ids[k] for k in present}
        for vid in sorted(self._in_sumo - present_ids):  # recording ended: it leaves
            traffic.remove(vid)
            self._in_sumo.discard(vid)
        motion = table.motion_at(step, present).tolist()  # x, y, heading, speed of each
        for k, (x, y, heading, speed) in zip(present.tolist(), motion, strict=True):
            vid = table.ids[k]
            if vid not in self._in_sumo:
                route = route_ahead(self.road, x, y, heading)
                traffic.add_vehicle(vid, route, table.length[k], table.width[k])
                self._in_sumo.add(vid)
            traffic.move(vid, x, y, heading, speed)
            if any(math.hypot(x - ex, y - ey) <= self.radius for ex, ey in egos):
                table.hand_over(k)
                self._in_sumo.discard(vid)
                traffic.release(vid, speed)
