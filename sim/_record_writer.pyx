"""Compiled writes of an arrays observation into its record: what
:class:`sim.observation_record.ObservationRecord` does by ``struct`` and numpy assignments, as C
stores of the same bytes (float64 to float32 and to int32 by C's conversions, as ``struct``'s and
numpy's casts; events as their truth) (``sim/compiled.py``)."""

from libc.stdint cimport int32_t
from libc.string cimport memcpy, memset

# The head's leaves, in the layout's order (sim.observation_arrays._leaf_specs): four scalars,
# the events, the ego's fields (EGO_FIELDS), its lane index, the goal's position and radius.
cdef enum:
    _SCALARS = 4
    _EVENTS = 8
    _EGO = _SCALARS + _EVENTS
    _LANE_INDEX = _EGO + 13
    _GOAL_POSITION = _LANE_INDEX + 1
    _GOAL_RADIUS = _GOAL_POSITION + 1
    HEAD_LEAVES = _GOAL_RADIUS + 1


cdef inline void _put_f32(unsigned char[::1] record, Py_ssize_t at, double value) noexcept:
    cdef float f = <float>value
    memcpy(&record[at], &f, 4)


cdef inline void _put_i32(unsigned char[::1] record, Py_ssize_t at, int32_t value) noexcept:
    memcpy(&record[at], &value, 4)


cdef inline void _put_vector(unsigned char[::1] record, Py_ssize_t at, double a, double b,
                             double c) noexcept:
    _put_f32(record, at, a)
    _put_f32(record, at + 4, b)
    _put_f32(record, at + 8, c)


cdef class RecordWriter:
    """Writes whole observations into records of one layout: the head's leaves at ``head_at``
    (their offsets in the layout's order, ending at ``head_end``; the bytes between them zero,
    as ``struct`` pads), the neighbours over one of ``neighbour_blanks`` (the neighbours' bytes
    with the first n slots taken, for each n), each value at its slot of ``neighbour_slots``
    (float32 units from ``neighbour_floats_at``) and the lanes' indices from
    ``neighbour_lanes_at``, and the waypoint paths over ``path_blank`` (nothing written) at
    ``path_offsets`` (mask, position, lane index, the four floats, slots of each float)."""

    cdef Py_ssize_t head_end
    cdef Py_ssize_t head_at[HEAD_LEAVES]
    cdef Py_ssize_t neighbours_at, neighbour_floats_at, neighbour_lanes_at
    cdef const long[:, ::1] neighbour_slots
    cdef list neighbour_blanks
    cdef bytes path_blank
    cdef Py_ssize_t paths_at, per_path, mask_at, pos_at, lane_at, floats_at, slots

    def __init__(self, head_at, Py_ssize_t head_end, Py_ssize_t neighbours_at,
                 list neighbour_blanks, Py_ssize_t neighbour_floats_at, neighbour_slots,
                 Py_ssize_t neighbour_lanes_at, Py_ssize_t paths_at, bytes path_blank,
                 Py_ssize_t per_path, path_offsets):
        if len(head_at) != HEAD_LEAVES:
            raise ValueError(f"{len(head_at)} head leaves, the writer knows {HEAD_LEAVES}")
        for i in range(HEAD_LEAVES):
            self.head_at[i] = head_at[i]
        self.head_end = head_end
        self.neighbours_at, self.neighbour_blanks = neighbours_at, neighbour_blanks
        self.neighbour_floats_at, self.neighbour_slots = neighbour_floats_at, neighbour_slots
        self.neighbour_lanes_at = neighbour_lanes_at
        self.paths_at, self.path_blank, self.per_path = paths_at, path_blank, per_path
        self.mask_at, self.pos_at, self.lane_at, self.floats_at, self.slots = path_offsets

    def write(self, unsigned char[::1] record, vehicle, long step, double dt, double elapsed,
              lane, events, const double[:, :] neighbours, list neighbour_lanes,
              const double[:, :] waypoints, list counts):
        """The observation of ``vehicle`` (a MissionVehicle) after ``step``: its ``lane`` (a
        LanePosition), ``events`` (Events, in EVENT_NAMES order), the first
        len(``neighbour_lanes``) rows of ``neighbours`` (VehicleStates values) and their lanes,
        and the ``waypoints`` of paths of ``counts`` points (WaypointArrays.values)."""
        self._write_head(record, vehicle, step, dt, elapsed, lane, events)
        self._write_neighbours(record, neighbours, neighbour_lanes)
        self._write_waypoints(record, waypoints, counts)

    cdef void _write_head(self, unsigned char[::1] record, vehicle, long step, double dt,
                          double elapsed, lane, events) except *:
        cdef Py_ssize_t *at = self.head_at
        pose, k, mission = vehicle.pose, vehicle.kinematics, vehicle.mission
        box, goal = mission.vehicle, mission.goal
        memset(&record[0], 0, self.head_end)
        _put_f32(record, at[0], dt)
        _put_i32(record, at[1], step)
        _put_f32(record, at[2], elapsed)
        _put_f32(record, at[3], vehicle.distance_travelled)
        cdef int i
        for i in range(_EVENTS):
            record[at[_SCALARS + i]] = 1 if events[i] else 0
        cdef Py_ssize_t *ego = &at[_EGO]
        vx, vy = k.velocity
        ax, ay = k.acceleration
        jx, jy = k.jerk
        yaw_rate = k.yaw_rate
        _put_vector(record, ego[0], pose.x, pose.y, 0.0)  # position
        _put_f32(record, ego[1], pose.heading)
        _put_f32(record, ego[2], pose.speed)
        _put_vector(record, ego[3], box.length, box.width, box.height)  # bounding box
        _put_f32(record, ego[4], pose.steering)
        _put_f32(record, ego[5], yaw_rate)
        _put_f32(record, ego[6], lane.s)  # lane position
        _put_f32(record, ego[6] + 4, lane.t)
        _put_vector(record, ego[7], vx, vy, 0.0)  # linear velocity
        _put_vector(record, ego[8], 0.0, 0.0, yaw_rate)  # angular velocity
        _put_vector(record, ego[9], ax, ay, 0.0)  # linear acceleration
        _put_vector(record, ego[10], 0.0, 0.0, k.angular_acceleration)
        _put_vector(record, ego[11], jx, jy, 0.0)  # linear jerk
        _put_vector(record, ego[12], 0.0, 0.0, k.angular_jerk)
        _put_i32(record, at[_LANE_INDEX], lane.lane.index)
        gx, gy = goal.position
        _put_f32(record, at[_GOAL_POSITION], gx)
        _put_f32(record, at[_GOAL_POSITION] + 4, gy)
        _put_f32(record, at[_GOAL_RADIUS], goal.radius)

    cdef void _write_neighbours(self, unsigned char[::1] record, const double[:, :] values,
                                list lanes) except *:
        cdef Py_ssize_t n = len(lanes), i, j
        cdef const unsigned char[::1] blank = self.neighbour_blanks[n]
        memcpy(&record[self.neighbours_at], &blank[0], blank.shape[0])
        for i in range(n):
            for j in range(6):
                _put_f32(record, self.neighbour_floats_at + 4 * self.neighbour_slots[i, j],
                         values[i, j])
            _put_i32(record, self.neighbour_lanes_at + 4 * i, lanes[i].index)

    cdef void _write_waypoints(self, unsigned char[::1] record, const double[:, :] values,
                               list counts) except *:
        """Each path's points (a column each, path after path) into its ``per_path`` slots:
        mask 1, position (x, y), the four floats, the lane index (numpy's cast of the float:
        truncation)."""
        cdef const unsigned char[::1] blank = self.path_blank
        memcpy(&record[self.paths_at], &blank[0], blank.shape[0])
        cdef Py_ssize_t path = 0, k, point = 0, slot, row
        for count in counts:
            for k in range(<Py_ssize_t>count):
                slot = path * self.per_path + k
                record[self.mask_at + slot] = 1
                _put_f32(record, self.pos_at + 8 * slot, values[0, point])
                _put_f32(record, self.pos_at + 8 * slot + 4, values[1, point])
                for row in range(4):
                    _put_f32(record, self.floats_at + 4 * (row * self.slots + slot),
                             values[2 + row, point])
                _put_i32(record, self.lane_at + 4 * slot, <int32_t>values[6, point])
                point += 1
            path += 1
