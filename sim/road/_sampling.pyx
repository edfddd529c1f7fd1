"""Compiled waypoint sampling: :meth:`sim.road.centrelines.CentrelineTable.sample`'s search and
interpolation, with its arithmetic operation for operation (``sim/compiled.py``)."""

import numpy as np

from libc.math cimport rint

# CentrelineTable.values' rows (sim/road/centrelines.py)
cdef enum:
    _CUM, _SLOPE_X, _SLOPE_Y, X, Y, HEADING, WIDTH, SPEED_LIMIT, OFFSET, INDEX


def sample(const double[:, ::1] table, const long[::1] first_column, const long[::1] vertices,
           list pieces, bint negative_zeros):
    """The (7, points) waypoint values of ``pieces`` (lane ordinal, first offset, count): rows X
    to INDEX of the table's column at each offset (its lane's last vertex at or before it, as
    the reference's search finds it), x and y interpolated as np.interp does and rounded to
    0.1 mm as ndarray.round(4) does (times 10,000, rint, divided by 10,000)."""
    cdef Py_ssize_t total = 0, p, k, lo, hi, mid, col, at = 0, count
    for piece in pieces:
        total += <Py_ssize_t>piece[2]
    out = np.empty((INDEX - X + 1, total))
    cdef double[:, ::1] v = out
    cdef double first_s, s, ds, value
    cdef long lane
    cdef int row
    for piece in pieces:
        lane, first_s, count = piece
        for k in range(count):
            s = first_s + <double>k
            # bisect_right over the lane's vertex offsets
            lo, hi = 0, vertices[lane]
            while lo < hi:
                mid = (lo + hi) // 2
                if s < table[_CUM, first_column[lane] + mid]:
                    hi = mid
                else:
                    lo = mid + 1
            col = first_column[lane] + lo - 1
            ds = s - table[_CUM, col]
            for row in range(2):
                value = table[X + row, col]
                if not (negative_zeros and ds == 0.0):
                    value = table[_SLOPE_X + row, col] * ds + value
                v[row, at] = rint(value * 10000.0) / 10000.0
            v[HEADING - X, at] = table[HEADING, col]
            v[WIDTH - X, at] = table[WIDTH, col]
            v[SPEED_LIMIT - X, at] = table[SPEED_LIMIT, col]
            v[OFFSET - X, at] = s
            v[INDEX - X, at] = table[INDEX, col]
            at += 1
    return out
