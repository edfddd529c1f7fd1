"""Compiled lane projection and nearest-lane search: :meth:`sim.road.lane.Lane.project` and the
grid part of :meth:`sim.road.network.RoadNetwork.nearest_lane`, with their arithmetic operation
for operation (``sim/compiled.py``)."""

from math import hypot as _py_hypot  # Python's, not the C library's: they differ in the last bit

from libc.math cimport floor, pow, sqrt

from sim._pymath cimport py_max, py_min, py_remainder

cdef double _CELL = 4.0
cdef double _CELL_REACH_D2 = 9.0
cdef double _TIE_DISTANCE = 0.5
cdef double _GRID_REACH = 4.0
cdef double _TAU = 6.283185307179586  # 2 * math.pi
# Cells list a few dozen segments at most; one listing more is left to the reference.
cdef enum:
    _MAX_LISTED = 256


cdef class LaneShape:
    """A lane's centreline as C arrays, and :meth:`Lane.project` on it."""

    cdef const double[:, ::1] pts
    cdef const double[::1] len2, frame_len, cum, heading
    cdef readonly object cells  # the lane's grid (Lane._make_cells) for long lanes, else None
    cdef int n

    def __init__(self, pts, len2, frame_len, cum, heading, cells):
        self.pts, self.len2, self.frame_len = pts, len2, frame_len
        self.cum, self.heading, self.cells = cum, heading, cells
        self.n = pts.shape[0]

    def project(self, double x, double y):
        """(s, t, heading) as :meth:`Lane.project` gives them."""
        cdef int i, best_i = 0
        cdef double x0, y0, dx, dy, rx, ry, u, d2, ex, ey, best_d2 = float("inf"), best_u = 0.0
        if self.cells is None:
            # Lane.project's loop: squares by pow, as Python's ``**`` does.
            for i in range(self.n - 1):
                x0, y0 = self.pts[i, 0], self.pts[i, 1]
                dx, dy = self.pts[i + 1, 0] - x0, self.pts[i + 1, 1] - y0
                rx, ry = x - x0, y - y0
                u = py_min(py_max((rx * dx + ry * dy) / py_max(dx * dx + dy * dy, 1e-12), 0.0), 1.0)
                d2 = pow(rx - dx * u, 2.0) + pow(ry - dy * u, 2.0)
                if d2 < best_d2:
                    best_d2, best_i, best_u = d2, i, u
            return self._frame(best_i, best_u, x, y)
        # Lane._project_long: the segments listed in the point's cell, squares by multiplying.
        listed = self.cells.get((<long>floor(x / _CELL), <long>floor(y / _CELL)), ())
        for i in listed:
            x0, y0 = self.pts[i, 0], self.pts[i, 1]
            dx, dy = self.pts[i + 1, 0] - x0, self.pts[i + 1, 1] - y0
            rx, ry = x - x0, y - y0
            u = py_min(py_max((rx * dx + ry * dy) / self.len2[i], 0.0), 1.0)
            ex, ey = rx - dx * u, ry - dy * u
            d2 = ex * ex + ey * ey
            if d2 < best_d2:
                best_d2, best_i, best_u = d2, i, u
        if best_d2 < _CELL_REACH_D2:
            return self._frame(best_i, best_u, x, y)
        # Lane._project_vectorised: every segment, the first nearest (numpy's argmin).
        best_d2 = float("inf")
        for i in range(self.n - 1):
            x0, y0 = self.pts[i, 0], self.pts[i, 1]
            dx, dy = self.pts[i + 1, 0] - x0, self.pts[i + 1, 1] - y0
            rx, ry = x - x0, y - y0
            u = py_min(py_max((rx * dx + ry * dy) / self.len2[i], 0.0), 1.0)
            ex, ey = rx - dx * u, ry - dy * u
            d2 = ex * ex + ey * ey
            if d2 < best_d2 or i == 0:
                best_d2, best_i, best_u = d2, i, u
        return self._frame(best_i, best_u, x, y)

    cdef tuple _frame(self, int i, double u, double x, double y):
        cdef double x0 = self.pts[i, 0], y0 = self.pts[i, 1]
        cdef double x1 = self.pts[i + 1, 0], y1 = self.pts[i + 1, 1]
        cdef double seg_len = self.frame_len[i]
        cdef double t = ((x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)) / seg_len
        cdef double s = self.cum[i] + u * seg_len
        return s, t, self.heading[i]


cdef inline bint _before(double d, double u, long k, double d2, double u2, long k2) noexcept:
    """Whether the tuple (d, u, k) is less than (d2, u2, k2), as Python compares them."""
    if d != d2:
        return d < d2
    if u != u2:
        return u < u2
    return k < k2


def grid_nearest(
    const double[:, ::1] seg,
    const long[::1] seg_lane,
    const double[::1] seg_heading,
    const long[::1] listed,
    double x,
    double y,
    heading,
):
    """RoadNetwork.nearest_lane from the segments ``listed`` in the point's grid cell: (lane
    ordinal, s, t, lane heading, distance, segment), or None where the reference searches its
    tree instead (nothing near enough in the cell). ``seg`` rows: x, y, dx, dy, length squared
    and length of each index segment.

    Python's ``math.hypot`` (its own algorithm, not the C library's) measures every candidate
    that can be the nearest or within the tie distance of it; the others cannot matter."""
    cdef Py_ssize_t m = listed.shape[0], j
    if m == 0 or m > _MAX_LISTED:
        return None
    cdef double u[_MAX_LISTED]
    cdef double d[_MAX_LISTED]
    cdef double rx, ry, dx, dy, ex, ey, nearest2 = float("inf"), limit
    cdef long k
    for j in range(m):
        k = listed[j]
        rx, ry = x - seg[k, 0], y - seg[k, 1]
        dx, dy = seg[k, 2], seg[k, 3]
        u[j] = (rx * dx + ry * dy) / seg[k, 4]
        u[j] = 0.0 if u[j] < 0.0 else 1.0 if u[j] > 1.0 else u[j]
        ex, ey = rx - dx * u[j], ry - dy * u[j]
        d[j] = ex * ex + ey * ey
        if d[j] < nearest2:
            nearest2 = d[j]
    # |hypot - sqrt(d2)| is a few units in the last place: this margin is far wider.
    limit = sqrt(nearest2) + _TIE_DISTANCE
    limit = limit + 1e-9 + 1e-12 * limit
    cdef long best = -1
    for j in range(m):
        if sqrt(d[j]) > limit:
            d[j] = -1.0  # cannot matter
            continue
        k = listed[j]
        rx, ry = x - seg[k, 0], y - seg[k, 1]
        d[j] = _py_hypot(rx - seg[k, 2] * u[j], ry - seg[k, 3] * u[j])
        if best < 0 or _before(d[j], u[j], k, d[best], u[best], listed[best]):
            best = j
    if d[best] + _TIE_DISTANCE > _GRID_REACH:
        return None
    cdef double bound = d[best] + _TIE_DISTANCE, angle, best_angle = 0.0
    cdef long aligned = -1, lane_k
    cdef double h
    cdef bint mixed = False
    if heading is not None:
        h = heading
        for j in range(m):
            if 0.0 <= d[j] <= bound and seg_lane[listed[j]] != seg_lane[listed[best]]:
                mixed = True
                break
        if mixed:
            for j in range(m):
                if 0.0 <= d[j] <= bound:
                    angle = abs(py_remainder(seg_heading[listed[j]] - h, _TAU))
                    if aligned < 0 or angle < best_angle:
                        aligned, best_angle = j, angle
            lane_k = seg_lane[listed[aligned]]
            best = -1
            for j in range(m):
                if d[j] >= 0.0 and seg_lane[listed[j]] == lane_k:
                    if best < 0 or _before(d[j], u[j], listed[j], d[best], u[best], listed[best]):
                        best = j
    k = listed[best]
    rx, ry = x - seg[k, 0], y - seg[k, 1]
    return (
        seg_lane[k],
        seg[k, 6] + u[best] * seg[k, 5],
        (seg[k, 2] * ry - seg[k, 3] * rx) / seg[k, 5],
        seg_heading[k],
        d[best],
        k,
    )

