"""Compiled collision test: :func:`sim.events.collisions` and
:func:`sim.geometry.box_overlaps_box`, with their arithmetic operation for operation
(``sim/compiled.py``)."""

from math import hypot as _py_hypot  # Python's, not the C library's: they differ in the last bit

from libc.math cimport cos, fabs, hypot, sin


cdef bint box_overlaps_box(double ax, double ay, double ah, double al, double aw,
                           double bx, double by, double bh, double bl, double bw) noexcept:
    cdef double dx = bx - ax, dy = by - ay
    cdef double ca = cos(ah), sa = sin(ah), cb = cos(bh), sb = sin(bh)
    cdef double axes[8]
    axes[:] = [ca, sa, -sa, ca, cb, sb, -sb, cb]
    cdef double ux, uy, ra, rb
    cdef int a
    for a in range(4):
        ux, uy = axes[2 * a], axes[2 * a + 1]
        ra = 0.5 * (al * fabs(ca * ux + sa * uy) + aw * fabs(-sa * ux + ca * uy))
        rb = 0.5 * (bl * fabs(cb * ux + sb * uy) + bw * fabs(-sb * ux + cb * uy))
        if fabs(dx * ux + dy * uy) > ra + rb:
            return False
    return True


def overlapping(double x, double y, double heading, double length, double width,
                const double[:, :] values, const double[:] distance):
    """Positions in ``values`` (VehicleStates rows) of the boxes overlapping the ego's, in row
    order; ``distance`` their centres' from (x, y)."""
    cdef double ego_reach = _py_hypot(length, width)
    cdef double reach
    cdef Py_ssize_t i
    cdef list hit = []
    for i in range(values.shape[0]):
        reach = hypot(values[i, 4], values[i, 5])
        reach += ego_reach
        reach *= 0.5
        if distance[i] <= reach and box_overlaps_box(
            x, y, heading, length, width,
            values[i, 0], values[i, 1], values[i, 2], values[i, 4], values[i, 5],
        ):
            hit.append(i)
    return hit

