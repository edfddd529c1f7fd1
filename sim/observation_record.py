"""An agent's arrays observation written by the simulator straight into its record.

When the agent or the environment asks for arrays (``Simulation(arrays=True)``), the simulator
skips the observation dict: each agent keeps one record of its
:class:`sim.observation_arrays.ObservationLayout`, with views over it made once, and every step
writes the ego's values, the neighbours' arrays and the sampled waypoints into it. The bytes are
those :class:`sim.observation_arrays.ObservationEncoder` makes of the dict (tests/sim hold them
equal), so the sandbox sends the record as it is and learn copies it once.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from sim.events import Events
from sim.mission_vehicle import MissionVehicle
from sim.observation import DEFAULT_HEIGHT, neighbour_lanes
from sim.observation_arrays import (
    NEIGHBOURS,
    PATHS,
    RASTER_NAMES,
    WAYPOINT_FIELDS,
    ObservationLayout,
    head_struct,
    head_values,
)
from sim.road import LanePosition, RoadNetwork
from sim.road.centrelines import WaypointArrays
from sim.vehicle.states import VehicleStates


class ArraysObservation(NamedTuple):
    """One agent's observation in the arrays format, as the simulator returns it."""

    record: bytearray  # the layout's record: rewritten at the agent's next observation
    arrays: dict  # the observation dict of arrays over ``record`` (ObservationLayout.arrays)
    done: bool  # True once: the agent's last observation
    events: Events
    road_id: str  # the ego's road and lane (strings: not in the arrays)
    lane_id: str


class ObservationRecord:
    """One agent's record and its views, rewritten in full at each of its observations."""

    def __init__(self, layout: ObservationLayout) -> None:
        self.layout = layout
        self.max_neighbours = layout.max_neighbours
        self.record = bytearray(layout.size)
        self.arrays = layout.arrays(self.record)
        self._head = head_struct(layout)
        nbr = self.arrays[NEIGHBOURS]
        self._nbr = (nbr["mask"], nbr["position"], nbr["heading"], nbr["speed"])
        self._nbr_box, self._nbr_lane = nbr["bounding_box"], nbr["lane_index"]
        self._nbr_bytes = _span(layout, NEIGHBOURS)
        paths = self.arrays[PATHS]
        self._per_path = layout.interface.waypoints_per_path
        self._path_mask = paths["mask"].reshape(-1)
        self._path_pos = paths["pos"].reshape(-1, 2)
        self._path_lane = paths["lane_index"].reshape(-1)
        # The per-waypoint floats lie back to back (as ObservationEncoder writes them): one
        # (fields, slots) block, written in one assignment.
        first = layout.leaf(PATHS, WAYPOINT_FIELDS[0])
        self._path_floats = np.ndarray(
            (len(WAYPOINT_FIELDS), self._path_mask.size), first.dtype, self.record, first.offset
        )
        self._path_bytes = _span(layout, PATHS)
        self._rasters = [name for name in RASTER_NAMES if name in self.arrays]

    def write(
        self,
        *,
        vehicle: MissionVehicle,
        step: int,
        dt: float,
        lane: LanePosition,
        events: Events,
        neighbours: VehicleStates,
        road: RoadNetwork,
        waypoints: WaypointArrays,
        rasters: dict[str, np.ndarray] | None,
        done: bool,
    ) -> ArraysObservation:
        """The values :func:`sim.observation.build_observation` would give, in place."""
        pose, k, mission = vehicle.pose, vehicle.kinematics, vehicle.mission
        self._head.pack_into(
            self.record,
            0,
            *head_values(
                (dt, step, round(step * dt, 6), vehicle.distance_travelled),
                events,
                [
                    (pose.x, pose.y, 0.0),
                    pose.heading,
                    pose.speed,
                    (mission.vehicle.length, mission.vehicle.width, mission.vehicle.height),
                    pose.steering,
                    k.yaw_rate,
                    (lane.s, lane.t),
                    (*k.velocity, 0.0),
                    (0.0, 0.0, k.yaw_rate),
                    (*k.acceleration, 0.0),
                    (0.0, 0.0, k.angular_acceleration),
                    (*k.jerk, 0.0),
                    (0.0, 0.0, k.angular_jerk),
                ],
                lane.lane.index,
                mission.goal.position,
                mission.goal.radius,
            ),
        )
        self._write_neighbours(neighbours, road)
        self._write_waypoints(waypoints)
        for name in self._rasters:
            self.arrays[name][...] = rasters[name]
        return ArraysObservation(
            self.record, self.arrays, done, events, lane.lane.edge_id, lane.lane.id
        )

    def _write_neighbours(self, neighbours: VehicleStates, road: RoadNetwork) -> None:
        start, end = self._nbr_bytes
        self.record[start:end] = bytes(end - start)
        n = min(len(neighbours), self.max_neighbours)
        if not n:
            return
        if len(neighbours) > n:  # the nearest are kept (the states are nearest first)
            neighbours = neighbours.first(n)
        values = neighbours.values  # x, y, heading, speed, length, width
        mask, position, heading, speed = self._nbr
        mask[:n] = 1
        position[:n, :2] = values[:, :2]
        heading[:n] = values[:, 2]
        speed[:n] = values[:, 3]
        box = self._nbr_box
        box[:n, :2] = values[:, 4:]
        box[:n, 2] = DEFAULT_HEIGHT
        self._nbr_lane[:n] = [lane.index for lane in neighbour_lanes(neighbours, road)]

    def _write_waypoints(self, waypoints: WaypointArrays) -> None:
        first, end = self._path_bytes
        self.record[first:end] = bytes(end - first)
        w, values = self._per_path, waypoints.values
        if values.shape[1] == w * len(waypoints.counts):  # every path full: the slots in a row
            at: slice | np.ndarray = slice(0, values.shape[1])
        else:
            at = np.concatenate(
                [np.arange(i * w, i * w + c) for i, c in enumerate(waypoints.counts)]
            )
        self._path_mask[at] = 1
        self._path_pos[at] = values[:2].T  # x, y
        self._path_floats[:, at] = values[2:6]  # heading .. lane_offset (WAYPOINT_FIELDS)
        self._path_lane[at] = values[6]


def _span(layout: ObservationLayout, group: str) -> tuple[int, int]:
    """[bytes] from the first leaf of ``group`` to the end of its last (they lie in a row)."""
    leaves = [leaf for leaf in layout.leaves if leaf.path[0] == group]
    return leaves[0].offset, leaves[-1].offset + leaves[-1].nbytes
