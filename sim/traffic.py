"""SUMO through libsumo: background traffic, and the mission vehicles as SUMO sees them.

libsumo holds one simulation per process and a second ``start()`` silently discards the first,
so exactly one :class:`SumoTraffic` may be open per process (checked). SUMO positions are the
front bumper and angles are degrees clockwise from north; this module converts to our
convention (centre, radians counter-clockwise from +x) at the boundary.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Collection
from pathlib import Path
from typing import Protocol

import numpy as np

from arena.errors import InfrastructureError
from sim.compiled import compiled
from sim.road import LanePosition
from sim.vehicle.states import VehicleStates

_neighbours = compiled("sim._neighbours")
_open_instance: SumoTraffic | None = None

# Speed / lane-change modes of SUMO: 0 = obey nothing (we or a script drive it); defaults below.
DEFAULT_SPEED_MODE = 31
DEFAULT_LANE_CHANGE_MODE = 1621
# moveToXY's keepRoute: 2 = the best-scored lane of any edge within 100 m, the vehicle exactly
# where it is told (on or off the road); 3 = the nearest lane of the vehicle's route, exactly there
SEARCH_NEAR, ALONG_ROUTE = 2, 3
# [m] room a front bumper keeps before its lane's end for the two mappings to agree (SUMO extends
# lane shapes by a little and measures the distance to a junction lane from its start)
LANE_END_ROOM = 1.0


class SumoError(InfrastructureError, RuntimeError):
    """SUMO failed (bad input files, internal error): the episode ends with simulator_error."""


def sumo_command(net: Path, routes: Path | None, seed: int, step_length: float) -> list[str]:
    cmd = ["sumo", "-n", str(net), "--step-length", str(step_length), "--seed", str(seed)]
    if routes is not None:
        cmd += ["-r", str(routes)]
    options = {
        "--collision.action": "none",  # we detect collisions with our own geometry
        "--time-to-teleport": "-1",
        "--no-step-log": "true",
        "--no-warnings": "true",
        "--duration-log.disable": "true",
        "--device.rerouting.probability": "0",
    }
    return [*cmd, *(item for pair in options.items() for item in pair)]


def sumo_mapping(
    lane: LanePosition | None, heading: float, half_length: float, route: Collection[str]
) -> int:
    """How SUMO maps a vehicle we move (moveToXY's keepRoute), given our map's ``lane`` under its
    centre, its ``heading`` [rad], ``half_length`` [m] and the edges of the ``route`` SUMO knows
    it by.

    SUMO maps the front bumper. Along the route SUMO tries only the route's lanes, the search
    near scores every lane within 100 m by distance (normalised by the farthest candidate),
    angle and being on the route (28 µs a move on a junction map against 4 µs on a straight
    road). Both choose the same lane, and so the same position on it, where the front bumper is
    on a lane of a route edge, off a junction, short of the lane's end and within a quarter of
    the lane's width of its centre: that lane is the nearest and outscores every other by
    SUMO's weights. Elsewhere the search near may choose another lane than our map: another of
    the junction lanes fanning out from one point, a ramp's lane beside the road, or none past
    the road's end. There, and off the route, the vehicle is searched for as before, so that
    SUMO's drivers see every ego where they always did (docs/performance.md)."""
    if lane is None or lane.lane.is_internal or lane.lane.edge_id not in route:
        return SEARCH_NEAR
    turn = heading - lane.heading
    front_s = lane.s + half_length * math.cos(turn)
    front_t = lane.t + half_length * math.sin(turn)
    if front_s + LANE_END_ROOM > lane.lane.length or abs(front_t) > lane.lane.width / 4:
        return SEARCH_NEAR
    return ALONG_ROUTE


def sumo_running() -> bool:
    """Whether this process already runs its one SUMO simulation."""
    return _open_instance is not None


class Traffic(Protocol):
    """What an episode asks of its traffic: a place for the mission vehicles, stepped with them,
    and the other vehicles around them."""

    def add_vehicle(
        self, vid: str, edges: list[str], length: float, width: float, height: float = 1.5
    ) -> None: ...
    def move(
        self,
        vid: str,
        x: float,
        y: float,
        heading: float,
        speed: float,
        lane: LanePosition | None = None,
    ) -> None: ...
    def remove(self, vid: str) -> None: ...
    def watch_around(self, vid: str, radius: float) -> None: ...
    def step(self) -> None: ...
    def vehicles_around(self, vid: str, skip: Collection[str] = ()) -> VehicleStates: ...
    def vehicles_within(
        self, vid: str, skip: Collection[str], x: float, y: float, radius: float
    ) -> tuple[VehicleStates, np.ndarray]: ...
    def is_in_network(self, vid: str) -> bool: ...
    def all_vehicles(self) -> VehicleStates: ...
    def close(self) -> None: ...


class SumoTraffic:
    """One running SUMO simulation. Create, :meth:`step`, read states, :meth:`close`."""

    def __init__(self, net: Path, routes: Path | None, seed: int, step_length: float) -> None:
        global _open_instance
        if _open_instance is not None:
            raise RuntimeError("one SUMO simulation per process: close the previous one first")
        import libsumo  # heavy; only in the process that simulates

        self._ls = libsumo
        self._tc = libsumo.constants
        try:
            libsumo.start(sumo_command(net, routes, seed, step_length))
        except libsumo.TraCIException as exc:
            raise SumoError(f"SUMO failed to start: {exc}") from exc
        _open_instance = self
        # vehicle id -> (half length, length, width) [m]
        self._dims: dict[str, tuple[float, float, float]] = {}
        self._routes = 0
        self._route_edges: dict[str, frozenset[str]] = {}  # vehicle id -> its route in SUMO
        self._around: dict[str, dict] = {}  # vehicle id -> SUMO's report of its surroundings
        self._vars = [
            self._tc.VAR_POSITION,
            self._tc.VAR_ANGLE,
            self._tc.VAR_SPEED,
            self._tc.VAR_LANE_ID,
        ]

    @property
    def libsumo(self):
        """The libsumo module, for scripted interventions (tests, triggers)."""
        return self._ls

    def step(self) -> None:
        try:
            self._ls.simulationStep()
        except self._ls.TraCIException as exc:
            raise SumoError(f"SUMO step failed: {exc}") from exc
        self._around.clear()

    @property
    def time(self) -> float:
        return self._ls.simulation.getTime()

    def close(self) -> None:
        global _open_instance
        if _open_instance is self:
            self._ls.close()
            _open_instance = None

    # --- vehicles we place ------------------------------------------------------------------

    def add_vehicle(
        self, vid: str, edges: list[str], length: float, width: float, height: float = 1.5
    ) -> None:
        """Add a vehicle that we move ourselves (speed and lane-change mode 0). It enters SUMO
        at the next step, where the next :meth:`move` puts it."""
        ls = self._ls
        type_id = f"__type_{vid}"
        if vid not in self._dims:
            ls.vehicletype.copy("DEFAULT_VEHTYPE", type_id)
            ls.vehicletype.setLength(type_id, length)
            ls.vehicletype.setWidth(type_id, width)
            ls.vehicletype.setHeight(type_id, height)
            ls.vehicletype.setMinGap(type_id, 0.0)
        self._routes += 1
        route_id = f"__route_{vid}_{self._routes}"
        try:
            ls.route.add(route_id, edges)
            ls.vehicle.add(vid, route_id, typeID=type_id, depart="now", departLane="best")
            ls.vehicle.setSpeedMode(vid, 0)
            ls.vehicle.setLaneChangeMode(vid, 0)
        except ls.TraCIException as exc:
            raise SumoError(f"cannot add vehicle {vid} on route {edges}: {exc}") from exc
        self._dims[vid] = (length / 2, length, width)
        self._route_edges[vid] = frozenset(edges)

    def move(
        self,
        vid: str,
        x: float,
        y: float,
        heading: float,
        speed: float,
        lane: LanePosition | None = None,
    ) -> None:
        """Put vehicle ``vid`` with its centre at (x, y) [m], ``heading`` [rad], ``speed`` [m/s]
        at the next step, exactly there (on the road or off it), on the lane SUMO maps it to so
        that its drivers see it: along its route where ``lane`` (our map's, at this pose) says
        that gives the same lane, else the best lane near (:func:`sumo_mapping`)."""
        half = self._dims[vid][0]
        fx, fy = x + half * math.cos(heading), y + half * math.sin(heading)
        angle = 90.0 - math.degrees(heading)
        keep_route = sumo_mapping(lane, heading, half, self._route_edges[vid])
        try:
            self._ls.vehicle.moveToXY(vid, "", -1, fx, fy, angle, keepRoute=keep_route)
            self._ls.vehicle.setPreviousSpeed(vid, speed)
        except self._ls.TraCIException:
            pass

    def release(self, vid: str, speed: float) -> None:
        """Hand a vehicle we were moving over to SUMO's driver model from now on."""
        ls = self._ls
        ls.vehicle.setSpeedMode(vid, DEFAULT_SPEED_MODE)
        ls.vehicle.setLaneChangeMode(vid, DEFAULT_LANE_CHANGE_MODE)
        ls.vehicle.setSpeed(vid, -1)
        ls.vehicle.setPreviousSpeed(vid, speed)

    def remove(self, vid: str) -> None:
        ls = self._ls
        with contextlib.suppress(ls.TraCIException):  # already left the network
            # A subscription outliving its vehicle makes SUMO's next step fail.
            ls.vehicle.unsubscribeContext(vid, self._tc.CMD_GET_VEHICLE_VARIABLE, 0.0)
            ls.vehicle.remove(vid)

    def force_lane_change(self, vid: str, lane_index: int, duration: float) -> None:
        """Make a SUMO vehicle change to ``lane_index`` now, ignoring safety (cut-in)."""
        self._ls.vehicle.setLaneChangeMode(vid, 0)
        self._ls.vehicle.changeLane(vid, lane_index, duration)

    # --- reading states ---------------------------------------------------------------------

    def watch_around(self, vid: str, radius: float) -> None:
        """Have SUMO report, after every step, the vehicles within ``radius`` [m] of ``vid``
        (SUMO measures between front bumpers: ask a little wider than needed)."""
        self._ls.vehicle.subscribeContext(
            vid, self._tc.CMD_GET_VEHICLE_VARIABLE, radius, self._vars
        )

    def _context(self, vid: str) -> dict:
        if vid not in self._around:
            self._around[vid] = self._ls.vehicle.getContextSubscriptionResults(vid)
        return self._around[vid]

    def vehicles_around(self, vid: str, skip: Collection[str] = ()) -> VehicleStates:
        """Vehicles SUMO found near watched vehicle ``vid`` at the last step, but for ``vid`` and
        the vehicles in ``skip``."""
        results = self._context(vid)
        if _neighbours is not None:
            ids, values, lanes = _neighbours.report_states(
                results, vid, skip, self._dims, self._measure, *self._vars
            )
            return VehicleStates.of(ids, values, lanes) if ids else VehicleStates.empty()
        return self._states(results, [v for v in results if v not in skip and v != vid])

    def vehicles_within(
        self, vid: str, skip: Collection[str], x: float, y: float, radius: float
    ) -> tuple[VehicleStates, np.ndarray]:
        """:meth:`vehicles_around` whose centre is within ``radius`` [m] of (x, y) [m], nearest
        first, and their distances [m] (:meth:`VehicleStates.nearest_first`)."""
        if _neighbours is not None:  # read, measured and ordered in one call
            ids, values, lanes, distance = _neighbours.report_nearest(
                self._context(vid), vid, skip, self._dims, self._measure, *self._vars, x, y, radius
            )
            return VehicleStates.of(ids, values, lanes) if ids else VehicleStates.empty(), distance
        return self.vehicles_around(vid, skip).nearest_first(x, y, radius)

    def is_in_network(self, vid: str) -> bool:
        """Whether vehicle ``vid`` is driving, or waiting to enter at the next step."""
        if vid in self._context(vid):  # a watched vehicle driving is in its own report: no
            return True  # need to list all vehicles (the common case, every ego every step)
        ls = self._ls
        return vid in ls.vehicle.getIDList() or vid in ls.simulation.getPendingVehicles()

    def all_vehicles(self) -> VehicleStates:
        """Every vehicle in the network (one call per vehicle: for recording scenes, not per
        ego step)."""
        ls, tc = self._ls, self._tc
        results = {
            v: {
                tc.VAR_POSITION: ls.vehicle.getPosition(v),
                tc.VAR_ANGLE: ls.vehicle.getAngle(v),
                tc.VAR_SPEED: ls.vehicle.getSpeed(v),
                tc.VAR_LANE_ID: ls.vehicle.getLaneID(v),
            }
            for v in ls.vehicle.getIDList()
        }
        return self._states(results, list(results))

    def _states(self, results: dict[str, dict], ids: list[str]) -> VehicleStates:
        """States of the vehicles ``ids`` from SUMO's ``results`` (id -> variable -> value)."""
        if not ids:
            return VehicleStates.empty()
        ids.sort()  # the order must not depend on SUMO's internal containers
        dims = self._dims
        position, angle, speed, lane = self._vars
        # Plain Python per vehicle and one array at the end: for the ~20 vehicles around an ego
        # this beats a dozen numpy calls. The same operations as numpy's radians, mod, cos and
        # sin, so the same values.
        pi, tau = math.pi, 2 * math.pi
        cos, sin, radians = math.cos, math.sin, math.radians
        flat: list[float] = []
        lanes = []
        for v in ids:
            r = results[v]
            half, length, width = dims.get(v) or self._measure(v)
            fx, fy = r[position]
            heading = pi - (pi - radians(90.0 - r[angle])) % tau
            flat += (
                fx - half * cos(heading),
                fy - half * sin(heading),
                heading,
                r[speed],
                length,
                width,
            )
            lanes.append(r[lane])
        return VehicleStates.of(ids, np.fromiter(flat, float, len(flat)).reshape(-1, 6), lanes)

    def _measure(self, vid: str) -> tuple[float, float, float]:
        """(half length, length, width) [m] of a vehicle SUMO made, asked once."""
        length = self._ls.vehicle.getLength(vid)
        size = self._dims[vid] = (length / 2, length, self._ls.vehicle.getWidth(vid))
        return size

    def lane_index(self, vid: str) -> int:
        return self._ls.vehicle.getLaneIndex(vid)

    def lane_position(self, vid: str) -> tuple[str, float]:
        return self._ls.vehicle.getLaneID(vid), self._ls.vehicle.getLanePosition(vid)


class MissionsOnlyTraffic:
    """The mission vehicles alone, for a scenario whose other vehicles are all replayed outside
    SUMO (:class:`sim.playback.ReplayTable`). SUMO would simulate nothing there that anyone
    reads: no SUMO driver reacts to a mission vehicle and none is ever around one. So no SUMO
    runs, which saves its start and, at every step, moving each mission vehicle into it and
    stepping it."""

    def __init__(self) -> None:
        self._present: set[str] = set()

    def add_vehicle(
        self, vid: str, edges: list[str], length: float, width: float, height: float = 1.5
    ) -> None:
        self._present.add(vid)

    def move(
        self,
        vid: str,
        x: float,
        y: float,
        heading: float,
        speed: float,
        lane: LanePosition | None = None,
    ) -> None:
        pass  # where a mission vehicle is, only the simulation's own state says

    def remove(self, vid: str) -> None:
        self._present.discard(vid)

    def watch_around(self, vid: str, radius: float) -> None:
        pass

    def step(self) -> None:
        pass

    def vehicles_around(self, vid: str, skip: Collection[str] = ()) -> VehicleStates:
        return VehicleStates.empty()

    def vehicles_within(
        self, vid: str, skip: Collection[str], x: float, y: float, radius: float
    ) -> tuple[VehicleStates, np.ndarray]:
        return self.vehicles_around(vid, skip).nearest_first(x, y, radius)

    def is_in_network(self, vid: str) -> bool:
        return vid in self._present

    def all_vehicles(self) -> VehicleStates:
        return VehicleStates.empty()

    def close(self) -> None:
        self._present.clear()
