"""Compiled writes of an arrays observation's neighbours and waypoints into its record:
:class:`sim.observation_record.ObservationRecord`'s numpy assignments as C loops, the same bytes
(float64 to float32 and to int32 by C's conversions, as numpy's casts) (``sim/compiled.py``)."""

from libc.stdint cimport int32_t
from libc.string cimport memcpy


cdef inline void _put_f32(unsigned char[::1] record, Py_ssize_t at, double value) noexcept:
    cdef float f = <float>value
    memcpy(&record[at], &f, 4)


cdef inline void _put_i32(unsigned char[::1] record, Py_ssize_t at, int32_t value) noexcept:
    memcpy(&record[at], &value, 4)


def write_neighbours(unsigned char[::1] record, Py_ssize_t floats_at, const long[:, ::1] slots,
                     const double[:, :] values, Py_ssize_t n, Py_ssize_t lanes_at, list lanes):
    """The first ``n`` rows of ``values`` (x, y, heading, speed, length, width) as float32 at
    their ``slots`` (float32 units from ``floats_at`` [bytes]), and the lanes' indices as int32
    from ``lanes_at`` [bytes]."""
    cdef Py_ssize_t i, j
    for i in range(n):
        for j in range(6):
            _put_f32(record, floats_at + 4 * slots[i, j], values[i, j])
        _put_i32(record, lanes_at + 4 * i, lanes[i].index)


def write_waypoints(unsigned char[::1] record, const double[:, :] values, list counts,
                    Py_ssize_t per_path, Py_ssize_t mask_at, Py_ssize_t pos_at,
                    Py_ssize_t lane_at, Py_ssize_t floats_at, Py_ssize_t slots):
    """Each path's points of ``values`` (x, y, heading, lane width, speed limit, offset, lane
    index; a column per point, path after path) into its ``per_path`` slots: mask 1, position
    (x, y) as float32, the four floats in their rows of ``slots`` float32, the lane index as
    int32 (numpy's cast of the float: truncation)."""
    cdef Py_ssize_t path = 0, k, point = 0, slot, row
    for count in counts:
        for k in range(<Py_ssize_t>count):
            slot = path * per_path + k
            record[mask_at + slot] = 1
            _put_f32(record, pos_at + 8 * slot, values[0, point])
            _put_f32(record, pos_at + 8 * slot + 4, values[1, point])
            for row in range(4):
                _put_f32(record, floats_at + 4 * (row * slots + slot), values[2 + row, point])
            _put_i32(record, lane_at + 4 * slot, <int32_t>values[6, point])
            point += 1
        path += 1
