"""An agent's arrays observation written by the simulator straight into its record.

When the agent or the environment asks for arrays (``Simulation(arrays=True)``), the simulator
skips the observation dict: each agent keeps one record of its
:class:`sim.observation_arrays.ObservationLayout`, with views over it made once, and every step
writes the ego's values, the neighbours' arrays and the sampled waypoints into it. The bytes are
those :class:`sim.observation_arrays.ObservationEncoder` makes of the dict (tests/sim hold them
equal), so the sandbox sends the record as it is and learn copies it once.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

import numpy as np

from sim.compiled import compiled
from sim.events import Events
from sim.mission_vehicle import MissionVehicle
from sim.observation import DEFAULT_HEIGHT, neighbour_lanes
from sim.observation_arrays import (
    F32,
    I32,
    NEIGHBOURS,
    PATHS,
    RASTER_NAMES,
    WAYPOINT_FIELDS,
    ObservationLayout,
    head_leaves,
    head_struct,
    head_values,
)
from sim.road import LanePosition, RoadNetwork
from sim.road.centrelines import WaypointArrays
from sim.vehicle.states import VehicleStates

_record_writer = compiled("sim._record_writer")


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
        # The first n neighbours' lane indices packed by one struct per n: cheaper than numpy's
        # conversion of a short list.
        lane_index = layout.leaf(NEIGHBOURS, "lane_index")
        assert lane_index.dtype == I32, "packed as '<i'"
        self._nbr_lane_at = lane_index.offset
        self._nbr_lane = [struct.Struct(f"<{n}i") for n in range(self.max_neighbours + 1)]
        self._nbr_bytes = _span(layout, NEIGHBOURS)
        floats_at, slots, self._nbr_blank = _neighbour_slots(layout)
        # The slots of the first n neighbours' values, flat, for each n: no index array per step.
        self._nbr_slots = [slots[:n].ravel() for n in range(self.max_neighbours + 1)]
        self._nbr_floats = np.ndarray((8 * self.max_neighbours,), F32, self.record, floats_at)
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
        # The paths' bytes with the first k paths' mask set and nothing else written, for each k:
        # full paths (the usual case) are then one copy and their values.
        start, end = self._path_bytes
        mask_at = layout.leaf(PATHS, "mask").offset - start
        self._path_blank = []
        for k in range(self._path_mask.size // self._per_path + 1):
            block = bytearray(end - start)
            block[mask_at : mask_at + k * self._per_path] = b"\x01" * (k * self._per_path)
            self._path_blank.append(bytes(block))
        self._rasters = [name for name in RASTER_NAMES if name in self.arrays]
        # The compiled core writes the head, the neighbours and the paths in one call.
        self._writer = None
        if _record_writer is not None:
            head = head_leaves(layout)
            self._writer = _record_writer.RecordWriter(
                [leaf.offset for leaf in head],
                head[-1].offset + head[-1].nbytes,
                self._nbr_bytes[0],
                self._nbr_blank,
                floats_at,
                np.ascontiguousarray(slots, np.int64),
                self._nbr_lane_at,
                self._path_bytes[0],
                self._path_blank[0],
                self._per_path,
                (  # [bytes] each point's mask, position, lane index and floats; the slots
                    layout.leaf(PATHS, "mask").offset,
                    layout.leaf(PATHS, "pos").offset,
                    layout.leaf(PATHS, "lane_index").offset,
                    first.offset,
                    self._path_mask.size,
                ),
            )

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
        elapsed = round(step * dt, 6)
        if self._writer is not None:
            n = min(len(neighbours), self.max_neighbours)
            if len(neighbours) > n:  # the nearest are kept (the states are nearest first)
                neighbours = neighbours.first(n)
            self._writer.write(
                self.record,
                vehicle,
                step,
                dt,
                elapsed,
                lane,
                events,
                neighbours.values,
                neighbour_lanes(neighbours, road),
                waypoints.values,
                waypoints.counts,
            )
        else:
            self._write_head(vehicle, step, dt, elapsed, lane, events)
            self._write_neighbours(neighbours, road)
            self._write_waypoints(waypoints)
        for name in self._rasters:
            self.arrays[name][...] = rasters[name]
        return ArraysObservation(
            self.record, self.arrays, done, events, lane.lane.edge_id, lane.lane.id
        )

    def _write_head(
        self,
        vehicle: MissionVehicle,
        step: int,
        dt: float,
        elapsed: float,
        lane: LanePosition,
        events: Events,
    ) -> None:
        pose, k, mission = vehicle.pose, vehicle.kinematics, vehicle.mission
        self._head.pack_into(
            self.record,
            0,
            *head_values(
                (dt, step, elapsed, vehicle.distance_travelled),
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

    def _write_neighbours(self, neighbours: VehicleStates, road: RoadNetwork) -> None:
        n = min(len(neighbours), self.max_neighbours)
        start, end = self._nbr_bytes
        self.record[start:end] = self._nbr_blank[n]
        if not n:
            return
        if len(neighbours) > n:  # the nearest are kept (the states are nearest first)
            neighbours = neighbours.first(n)
        self._nbr_floats[self._nbr_slots[n]] = neighbours.values.ravel()
        self._nbr_lane[n].pack_into(
            self.record,
            self._nbr_lane_at,
            *[lane.index for lane in neighbour_lanes(neighbours, road)],
        )

    def _write_waypoints(self, waypoints: WaypointArrays) -> None:
        first, end = self._path_bytes
        w, values, counts = self._per_path, waypoints.values, waypoints.counts
        if values.shape[1] == w * len(counts):  # every path full: the slots in a row
            self.record[first:end] = self._path_blank[len(counts)]
            at: slice | np.ndarray = slice(0, values.shape[1])
        else:
            self.record[first:end] = self._path_blank[0]
            at = np.concatenate([np.arange(i * w, i * w + c) for i, c in enumerate(counts)])
            self._path_mask[at] = 1
        self._path_pos[at] = values[:2].T  # x, y
        self._path_floats[:, at] = values[2:6]  # heading .. lane_offset (WAYPOINT_FIELDS)
        self._path_lane[at] = values[6]


def _neighbour_slots(layout: ObservationLayout) -> tuple[int, np.ndarray, list[bytes]]:
    """The neighbours' float leaves, position to bounding_box, lie back to back: where they
    start [bytes], and where each value of a neighbour's :class:`VehicleStates` row (x, y,
    heading, speed, length, width) goes among them, for each slot (float32 units); and the
    neighbours' bytes with the first n slots taken (mask 1, default height) and nothing else
    written yet, for each n."""
    m = layout.max_neighbours
    first, last = layout.leaf(NEIGHBOURS, "position"), layout.leaf(NEIGHBOURS, "bounding_box")
    assert last.offset + last.nbytes - first.offset == 8 * m * 4, "float32 leaves back to back"
    i = np.arange(m)
    # position (m, 3), heading (m), speed (m), bounding_box (m, 3)
    slots = np.stack([3 * i, 3 * i + 1, 3 * m + i, 4 * m + i, 5 * m + 3 * i, 5 * m + 3 * i + 1], 1)
    start, end = _span(layout, NEIGHBOURS)
    mask_at = layout.leaf(NEIGHBOURS, "mask").offset - start
    blank = []
    for n in range(m + 1):
        block = bytearray(end - start)
        block[mask_at : mask_at + n] = b"\x01" * n
        floats = np.ndarray((8 * m,), first.dtype, block, first.offset - start)
        floats[5 * m + 3 * i[:n] + 2] = DEFAULT_HEIGHT
        blank.append(bytes(block))
    return first.offset, slots, blank


def _span(layout: ObservationLayout, group: str) -> tuple[int, int]:
    """[bytes] from the first leaf of ``group`` to the end of its last (they lie in a row)."""
    leaves = [leaf for leaf in layout.leaves if leaf.path[0] == group]
    return leaves[0].offset, leaves[-1].offset + leaves[-1].nbytes
