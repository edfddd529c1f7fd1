"""Compiled neighbours' states: :meth:`sim.traffic.SumoTraffic.vehicles_around`'s states from
SUMO's report, :meth:`sim.vehicle.states.VehicleStates.nearest_first`, and the two in one
(:meth:`sim.traffic.SumoTraffic.vehicles_within`), with their arithmetic operation for operation
(``sim/compiled.py``)."""

import numpy as np

from libc.math cimport cos, hypot, sin

from sim._pymath cimport py_mod


cdef double _PI = 3.141592653589793
cdef double _TAU = 6.283185307179586
cdef double _DEG_TO_RAD = 3.141592653589793 / 180.0  # math.radians' factor


def report_states(dict results, str vid, skip, dict dims, measure, position, angle, speed, lane):
    """(ids, values (n, 6), lane ids) of the vehicles of SUMO's report ``results`` (id ->
    variable -> value) but ``vid`` and those in ``skip``, ids sorted: SumoTraffic._states."""
    cdef list ids = [v for v in results if v != vid and v not in skip]
    ids.sort()
    cdef Py_ssize_t n = len(ids), i
    values = np.empty((n, 6))
    cdef double[:, ::1] out = values
    cdef list lanes = []
    cdef double half, heading, fx, fy
    cdef dict r
    for i in range(n):
        v = ids[i]
        r = results[v]
        size = dims.get(v)
        if size is None:
            size = measure(v)
        half = size[0]
        fx, fy = r[position]
        heading = _PI - py_mod(_PI - (90.0 - <double>r[angle]) * _DEG_TO_RAD, _TAU)
        out[i, 0] = fx - half * cos(heading)
        out[i, 1] = fy - half * sin(heading)
        out[i, 2] = heading
        out[i, 3] = r[speed]
        out[i, 4] = size[1]
        out[i, 5] = size[2]
        lanes.append(r[lane])
    return ids, values, lanes


def nearest_first(const double[:, :] values, double x, double y, double radius):
    """(order, distances) of the vehicles of ``values`` (VehicleStates rows) whose centre is
    within ``radius`` of (x, y), nearest first, ties in their order: the positions
    VehicleStates.nearest_first selects (numpy's hypot is the C library's)."""
    cdef Py_ssize_t n = values.shape[0], i, j, k = 0
    distance = np.empty(n)
    order = np.empty(n, dtype=np.intp)
    cdef double[::1] dist = distance
    cdef Py_ssize_t[::1] at = order
    cdef double d
    for i in range(n):
        d = hypot(values[i, 0] - x, values[i, 1] - y)
        if not d <= radius:
            continue
        # after every nearer or equally near one: a stable sort
        j = k
        while j > 0 and dist[j - 1] > d:
            dist[j] = dist[j - 1]
            at[j] = at[j - 1]
            j -= 1
        dist[j] = d
        at[j] = i
        k += 1
    if k < n:
        return order[:k], distance[:k]
    return order, distance


def report_nearest(dict results, str vid, skip, dict dims, measure, position, angle, speed,
                   lane, double x, double y, double radius):
    """:func:`report_states` and :func:`nearest_first` of them in one: (ids, values (k, 6),
    lane ids, distances) of the reported vehicles within ``radius`` of (x, y), nearest first
    (ties in id order), as VehicleStates.nearest_first selects them."""
    ids, values, lanes = report_states(results, vid, skip, dims, measure, position, angle,
                                       speed, lane)
    order, distance = nearest_first(values, x, y, radius)
    cdef const double[:, ::1] every = values
    cdef const Py_ssize_t[::1] at = order
    cdef Py_ssize_t k = at.shape[0], i, j
    near = np.empty((k, 6))
    cdef double[:, ::1] out = near
    for i in range(k):
        for j in range(6):
            out[i, j] = every[at[i], j]
    return [ids[at[i]] for i in range(k)], near, [lanes[at[i]] for i in range(k)], distance
