"""Snapshots of vehicle states as parallel numpy arrays (one row per vehicle)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class VehicleStates:
    """States of ``n`` vehicles at one instant. ``lane_id`` is "" where unknown (vehicles not
    driven by SUMO: our geometry fills it in when needed)."""

    ids: list[str]  # (n,)
    x: np.ndarray  # (n,) centre [m]
    y: np.ndarray  # (n,) centre [m]
    heading: np.ndarray  # (n,) [rad]
    speed: np.ndarray  # (n,) [m/s]
    length: np.ndarray  # (n,) [m]
    width: np.ndarray  # (n,) [m]
    lane_id: list[str]  # (n,)

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def empty(cls) -> VehicleStates:
        z = np.zeros(0)
        return cls([], z, z, z, z, z, z, [])

    @classmethod
    def concat(cls, parts: list[VehicleStates]) -> VehicleStates:
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        return cls(
            [i for p in parts for i in p.ids],
            *(np.concatenate([getattr(p, f) for p in parts]) for f in _ARRAYS),
            [lane for p in parts for lane in p.lane_id],
        )

    def select(self, index: np.ndarray) -> VehicleStates:
        """The vehicles at positions ``index`` (integer array), in that order."""
        at = index.tolist()  # list indexing with Python ints is several times faster
        return VehicleStates(
            [self.ids[i] for i in at],
            self.x[index],
            self.y[index],
            self.heading[index],
            self.speed[index],
            self.length[index],
            self.width[index],
            [self.lane_id[i] for i in at],
        )

    def nearest_first(self, x: float, y: float, radius: float) -> tuple[VehicleStates, np.ndarray]:
        """The vehicles whose centre is within ``radius`` [m] of (x, y) [m], nearest first (ties
        in their present order), and those distances [m]."""
        distance = np.hypot(self.x - x, self.y - y)
        keep = (distance <= radius).nonzero()[0]
        order = keep[np.argsort(distance[keep], kind="stable")]
        return self.select(order), distance[order]

    def without(self, ids: set[str]) -> VehicleStates:
        """These states minus the vehicles whose id is in ``ids``."""
        if not any(vid in ids for vid in self.ids):
            return self
        return self.select(np.array([i for i, v in enumerate(self.ids) if v not in ids], dtype=int))


@dataclass(frozen=True)
class Surroundings:
    """The vehicles around an ego, nearest first, and their centre distances from it."""

    vehicles: VehicleStates
    distance: np.ndarray  # (n,) [m]


_ARRAYS = ("x", "y", "heading", "speed", "length", "width")
