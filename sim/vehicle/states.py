"""Snapshots of vehicle states: one (n, 6) float matrix, a row per vehicle."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.compiled import compiled

_neighbours = compiled("sim._neighbours")

# The matrix's columns, in order; each is also an attribute (a view of its column).
FIELDS = ("x", "y", "heading", "speed", "length", "width")


class VehicleStates:
    """States of ``n`` vehicles at one instant: centre ``x``, ``y`` [m], ``heading`` [rad],
    ``speed`` [m/s], ``length``, ``width`` [m] as the columns of ``values`` (one matrix, so
    that selecting, reordering and joining vehicles is one numpy operation, not one per field),
    and ``ids`` and ``lane_id`` (``""`` where unknown: vehicles not driven by SUMO; our
    geometry fills it in when needed). Immutable by convention: shared between an episode's
    observation, record and rasters."""

    __slots__ = ("ids", "lane_id", "values")

    def __init__(
        self,
        ids: list[str],
        x: np.ndarray,
        y: np.ndarray,
        heading: np.ndarray,
        speed: np.ndarray,
        length: np.ndarray,
        width: np.ndarray,
        lane_id: list[str],
    ) -> None:
        columns = (x, y, heading, speed, length, width)
        self.ids = ids
        self.values = np.stack(columns, axis=1) if len(ids) else np.zeros((0, len(FIELDS)))
        self.lane_id = lane_id

    @classmethod
    def of(cls, ids: list[str], values: np.ndarray, lane_id: list[str]) -> VehicleStates:
        """States over ``values`` (n, 6) in :data:`FIELDS` order, not copied."""
        states = cls.__new__(cls)
        states.ids, states.values, states.lane_id = ids, values, lane_id
        return states

    x = property(lambda self: self.values[:, 0], doc="(n,) centre [m]")
    y = property(lambda self: self.values[:, 1], doc="(n,) centre [m]")
    heading = property(lambda self: self.values[:, 2], doc="(n,) [rad]")
    speed = property(lambda self: self.values[:, 3], doc="(n,) [m/s]")
    length = property(lambda self: self.values[:, 4], doc="(n,) [m]")
    width = property(lambda self: self.values[:, 5], doc="(n,) [m]")

    def __len__(self) -> int:
        return len(self.ids)

    def __repr__(self) -> str:
        return f"VehicleStates({self.ids!r})"

    @classmethod
    def empty(cls) -> VehicleStates:
        return _NONE  # immutable, so one serves every caller (several per step)

    @classmethod
    def concat(cls, parts: list[VehicleStates]) -> VehicleStates:
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        return cls.of(
            [i for p in parts for i in p.ids],
            np.concatenate([p.values for p in parts]),
            [lane for p in parts for lane in p.lane_id],
        )

    def select(self, index: np.ndarray) -> VehicleStates:
        """The vehicles at positions ``index`` (integer array), in that order."""
        at = index.tolist()  # list indexing with Python ints is several times faster
        ids, lanes = self.ids, self.lane_id
        return VehicleStates.of(
            [ids[i] for i in at], self.values.take(index, 0), [lanes[i] for i in at]
        )

    def first(self, n: int) -> VehicleStates:
        """The first ``n`` vehicles (their values a view of these)."""
        return VehicleStates.of(self.ids[:n], self.values[:n], self.lane_id[:n])

    def nearest_first(self, x: float, y: float, radius: float) -> tuple[VehicleStates, np.ndarray]:
        """The vehicles whose centre is within ``radius`` [m] of (x, y) [m], nearest first (ties
        in their present order), and those distances [m]."""
        values = self.values
        if _neighbours is not None:
            order, distance = _neighbours.nearest_first(values, x, y, radius)
            return self.select(order), distance
        distance = np.hypot(values[:, 0] - x, values[:, 1] - y)
        # A stable sort of all, cut after those within the radius: the same order as sorting
        # only those, with fewer numpy calls (each costs more than the arithmetic here).
        order = distance.argsort(kind="stable")  # the method: np.argsort adds a wrapper
        distance = distance.take(order)
        within = int(distance.searchsorted(radius, side="right"))
        if within < len(order):
            order, distance = order[:within], distance[:within]
        return self.select(order), distance

    def without(self, ids: set[str]) -> VehicleStates:
        """These states minus the vehicles whose id is in ``ids``."""
        if not any(vid in ids for vid in self.ids):
            return self
        return self.select(np.array([i for i, v in enumerate(self.ids) if v not in ids], dtype=int))


_NONE = VehicleStates.of([], np.zeros((0, len(FIELDS))), [])
_NONE.values.flags.writeable = False


@dataclass(frozen=True)
class Surroundings:
    """The vehicles around an ego, nearest first, and their centre distances from it."""

    vehicles: VehicleStates
    distance: np.ndarray  # (n,) [m]
