"""Compiled waypoint paths: :func:`sim.road.waypoints.waypoint_arrays`'s walk along the lanes and
:meth:`sim.road.centrelines.CentrelineTable.sample`'s search and interpolation, with their
arithmetic operation for operation (``sim/compiled.py``)."""

import numpy as np

from libc.math cimport ceil, rint

# CentrelineTable.values' rows (sim/road/centrelines.py)
cdef enum:
    _CUM, _SLOPE_X, _SLOPE_Y, X, Y, HEADING, WIDTH, SPEED_LIMIT, OFFSET, INDEX

cdef double _SPACING = 1.0  # sim.road.lane.WAYPOINT_SPACING
cdef long _MAX_LANE_HOPS = 256  # sim.road.waypoints._MAX_LANE_HOPS


cdef object _sample(const double[:, ::1] table, const long[::1] first_column,
                    const long[::1] vertices, list pieces, bint negative_zeros):
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


def paths(const double[:, ::1] table, const long[::1] first_column, const long[::1] vertices,
          list starts, long n, successor, bint negative_zeros):
    """:func:`sim.road.waypoints.waypoint_arrays` from lane ordinals: (counts, values, pieces)
    of the paths of up to ``n`` points from each (lane ordinal, s) of ``starts``, each lane
    giving the points :meth:`Lane.waypoint_count` says and ``successor(ordinal)`` (-1 at a dead
    end) the next lane; a path with no point holds its last lane's end. ``pieces``: (lane
    ordinal, points) of each lane with points, in order; ``values`` as :func:`sample`'s."""
    cdef list pieces = [], counts = [], walk
    cdef long lane, after, count, on_lane, taken, hop
    cdef double first_s, start, length
    for start_lane, s in starts:
        lane, first_s, count, walk = start_lane, s, 0, []
        for hop in range(_MAX_LANE_HOPS):
            length = table[_CUM, first_column[lane] + vertices[lane] - 1]
            start = first_s if not 0.0 > first_s else 0.0  # Python's max(first_s, 0.0)
            on_lane = <long>ceil((length - start) / _SPACING - 1e-9)
            if on_lane < 0:
                on_lane = 0
            taken = n - count if n - count < on_lane else on_lane
            walk.append((lane, start, taken))
            count += taken
            if count >= n:
                break
            first_s = first_s + <double>on_lane * _SPACING - length
            after = successor(lane)
            if after < 0:
                break
            lane = after
        if not count:
            length = table[_CUM, first_column[lane] + vertices[lane] - 1]
            walk, count = [(lane, length, 1)], 1
        pieces += walk
        counts.append(count)
    kept = [piece for piece in pieces if piece[2]]
    values = _sample(table, first_column, vertices, kept, negative_zeros)
    return counts, values, [(piece[0], piece[2]) for piece in kept]
