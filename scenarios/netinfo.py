"""Read-only queries on a built map the generators need: lane poses, lengths, turn directions."""

from __future__ import annotations

import itertools
import math
from functools import lru_cache
from pathlib import Path

import sumolib
from sumolib.geomhelper import positionAtShapeOffset


class NetInfo:
    def __init__(self, net_path: Path) -> None:
        self.path = Path(net_path)
        self.net = sumolib.net.readNet(str(net_path), withInternal=True)

    def lanes(self, edge: str) -> int:
        return len(self.net.getEdge(edge).getLanes())

    def length(self, edge: str) -> float:
        return float(self.net.getEdge(edge).getLanes()[0].getLength())

    def driving_lanes(self, edge: str) -> list[int]:
        """Lane indices passenger cars may use (shoulders excluded)."""
        return [ln.getIndex() for ln in self.net.getEdge(edge).getLanes() if ln.allows("passenger")]

    def pose(self, edge: str, lane: int, s: float) -> tuple[float, float, float]:
        """Centre-line point and heading (x [m], y [m], heading [rad]) at offset ``s`` [m]."""
        shape = self.net.getEdge(edge).getLanes()[lane].getShape()
        x, y = positionAtShapeOffset(shape, s)
        # Heading of the shape segment holding s (the last one past the end).
        walked = 0.0
        for (x1, y1), (x2, y2) in itertools.pairwise(shape):
            walked += math.hypot(x2 - x1, y2 - y1)
            if walked >= s:
                break
        return (round(x, 3), round(y, 3), round(math.atan2(y2 - y1, x2 - x1), 5))

    def turn(self, src: str, direction: str) -> str | None:
        """The edge reached from ``src`` by a turn in SUMO's direction code ('l', 'r', 's')."""
        for conns in self.net.getEdge(src).getOutgoing().values():
            for conn in conns:
                if conn.getDirection() == direction:
                    return conn.getTo().getID()
        return None

    def speed(self, edge: str) -> float:
        return float(self.net.getEdge(edge).getSpeed())


@lru_cache(maxsize=64)
def net_info(net_path: Path) -> NetInfo:
    return NetInfo(net_path)
