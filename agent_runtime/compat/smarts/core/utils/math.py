"""SMARTS's math helpers (``smarts.core.utils.math``), with SMARTS's conventions: headings in
radians, 0 = north (+y), counter-clockwise, so heading h points along (-sin h, cos h)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np


def vec_2d(v: Sequence[float]) -> np.ndarray:
    """The first two components of ``v`` as an array (2,)."""
    return np.array(v[:2])


def radians_to_vec(radians: float) -> np.ndarray:
    """The unit vector (2,) a heading points along (0 = north)."""
    angle = (radians + math.pi * 0.5) % (2 * math.pi)
    return np.array((math.cos(angle), math.sin(angle)))


def vec_to_radians(v: Sequence[float]) -> float:
    """The heading of direction ``v`` in [0, 2 pi) (0 = north, counter-clockwise)."""
    r = math.atan2(v[1], v[0])
    return (r - math.pi * 0.5) % (2 * math.pi)


def clip(val: float, min_val: float, max_val: float) -> float:
    assert min_val <= max_val, f"min_val({min_val}) must be <= max_val({max_val})"
    return min_val if val < min_val else max_val if val > max_val else val


def lerp(a: float, b: float, p: float) -> float:
    """Linear interpolation from ``a`` (p = 0) to ``b`` (p = 1)."""
    return a * (1 - p) + b * p


def safe_division(n: float, d: float, default: float = math.inf) -> float:
    """``n / d``, or ``default`` (0 when ``n`` is 0) when ``d`` is 0."""
    if n == 0:
        return 0
    return default if d == 0 else n / d


def squared_dist(a: Sequence[float], b: Sequence[float]) -> float:
    delta = np.asarray(b) - np.asarray(a)
    return float(np.dot(delta, delta))


def euclidean_distance(p1: Sequence[float], p2: Sequence[float]) -> float:
    return math.hypot(p1[0] - p2[0], p1[1] - p2[1])


def signed_dist_to_line(point, line_point, line_dir_vec) -> float:
    """Distance from ``point`` to the line through ``line_point`` along ``line_dir_vec``:
    positive on the line's left, negative on its right."""
    p = vec_2d(point)
    p1 = np.asarray(line_point[:2], dtype=float)
    d = np.asarray(line_dir_vec[:2], dtype=float)
    offset = p - p1
    return float((d[0] * offset[1] - d[1] * offset[0]) / np.linalg.norm(d))


def min_angles_difference_signed(first: float, second: float) -> float:
    """The smallest signed angle from ``second`` to ``first`` [rad], in (-pi, pi]."""
    return ((first - second) + math.pi) % (2 * math.pi) - math.pi


def wrap_value(value: float, lower: float, upper: float) -> float:
    """``value`` wrapped into [lower, upper)."""
    return (value - lower) % (upper - lower) + lower


def constrain_angle(angle: float) -> float:
    """``angle`` [rad] wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def rotate_around_point(point, radians: float, origin=(0, 0)) -> np.ndarray:
    """``point`` turned ``radians`` clockwise around ``origin`` (SMARTS's convention)."""
    x, y = point[0], point[1]
    ox, oy = origin[0], origin[1]
    qx = ox + math.cos(radians) * (x - ox) + math.sin(radians) * (y - oy)
    qy = oy + -math.sin(radians) * (x - ox) + math.cos(radians) * (y - oy)
    return np.array([qx, qy])


def position_to_ego_frame(position, ego_position, ego_heading: float) -> list[float]:
    """A world ``position`` (3,) in the ego's frame: x right, y forward, z up."""
    transform = np.array(
        [
            [math.cos(-ego_heading), -math.sin(-ego_heading), 0],
            [math.sin(-ego_heading), math.cos(-ego_heading), 0],
            [0, 0, 1],
        ]
    )
    offset = np.array([*position, 0][:3], dtype=float) - np.array([*ego_position, 0][:3])
    return (transform @ offset).tolist()


def world_position_from_ego_frame(local_position, ego_world_position, ego_world_heading):
    """The inverse of :func:`position_to_ego_frame`."""
    transform = np.array(
        [
            [math.cos(ego_world_heading), -math.sin(ego_world_heading), 0],
            [math.sin(ego_world_heading), math.cos(ego_world_heading), 0],
            [0, 0, 1],
        ]
    )
    local = np.array([*local_position, 0][:3], dtype=float)
    return (transform @ local + np.array([*ego_world_position, 0][:3])).tolist()


def comp_vec_to_radians(v) -> float:
    """Heading of ``v`` wrapped into [-pi, pi) (0 = north)."""
    return constrain_angle(vec_to_radians(v))


def evaluate_bezier(points: Sequence, t: float) -> np.ndarray:
    """The point at ``t`` in [0, 1] of the Bezier curve with control ``points``."""
    pts = np.asarray(points, dtype=float)
    n = len(pts) - 1
    weights = np.array([math.comb(n, i) * t**i * (1 - t) ** (n - i) for i in range(n + 1)])
    return weights @ pts


def batches(items: Sequence, n: int) -> Iterable[Sequence]:
    """``items`` in consecutive slices of ``n``."""
    for start in range(0, len(items), n):
        yield items[start : start + n]


def fast_quaternion_from_angle(angle: float) -> np.ndarray:
    """The quaternion (x, y, z, w) of a rotation by ``angle`` about +z."""
    half = angle * 0.5
    return np.array([0.0, 0.0, math.sin(half), math.cos(half)])


def yaw_from_quaternion(q: Sequence[float]) -> float:
    """The rotation about +z [rad] of quaternion ``q`` (x, y, z, w)."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def line_intersect(a, b, c, d) -> np.ndarray | None:
    """Where segment a-b crosses segment c-d, or None."""
    r = np.asarray(b[:2], float) - np.asarray(a[:2], float)
    s = np.asarray(d[:2], float) - np.asarray(c[:2], float)
    denominator = r[0] * s[1] - r[1] * s[0]
    if denominator == 0:
        return None
    qp = np.asarray(c[:2], float) - np.asarray(a[:2], float)
    t = (qp[0] * s[1] - qp[1] * s[0]) / denominator
    u = (qp[0] * r[1] - qp[1] * r[0]) / denominator
    if 0 <= t <= 1 and 0 <= u <= 1:
        return np.asarray(a[:2], float) + t * r
    return None


def line_intersect_vectorized(a, b, c: np.ndarray, d: np.ndarray, ignore_start_pt=False) -> bool:
    """Whether segment a-b crosses any segment ``c[i]-d[i]`` (rows of (n, 2) arrays). With
    ``ignore_start_pt``, lines that only touch at the first segment's start do not count."""
    r = np.asarray(b[:2], float) - np.asarray(a[:2], float)
    s = np.asarray(d, float)[:, :2] - np.asarray(c, float)[:, :2]
    denominator = r[0] * s[:, 1] - r[1] * s[:, 0]
    if not np.any(denominator):
        return False
    qp = np.asarray(c, float)[:, :2] - np.asarray(a[:2], float)
    safe = np.where(denominator == 0, 1.0, denominator)
    along_ab = np.where(denominator == 0, -1.0, (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / safe)
    along_cd = np.where(denominator == 0, -1.0, (qp[:, 0] * r[1] - qp[:, 1] * r[0]) / safe)
    crossing = (along_ab >= 0) & (along_ab <= 1) & (along_cd >= 0) & (along_cd <= 1)
    if not np.any(crossing):
        return False
    return not ignore_start_pt or bool(np.any(crossing[1:])) or along_cd[0] > 0.0


def ray_boundary_intersect(ray_start, ray_end, boundary_pts, early_return=True):
    """Where the ray segment meets the polyline ``boundary_pts``: the first crossing found
    (``early_return``) or the nearest to ``ray_start``; None when it meets none."""
    size = len(ray_start)
    nearest, nearest_distance = None, math.inf
    for start, end in itertools.pairwise(boundary_pts):
        point = line_intersect(start[:size], end[:size], ray_start, ray_end)
        if point is None:
            continue
        if early_return:
            return point
        distance = float(np.linalg.norm(point - np.asarray(ray_start[:2], float)))
        if distance < nearest_distance:
            nearest, nearest_distance = point, distance
    return nearest


def rotate_cw_around_point(point, radians: float, origin=(0, 0)) -> np.ndarray:
    """comp-1's name of :func:`rotate_around_point` (clockwise)."""
    return rotate_around_point(point, radians, origin)


def sign(x) -> int:
    """-1 for a negative number, else 1."""
    return -1 if x < 0 else 1


def is_close(a: float, b: float, rel_tol: float = 1e-09, abs_tol: float = 0.0) -> bool:
    """``math.isclose``'s test, as SMARTS spells it."""
    return abs(a - b) <= max(rel_tol * max(abs(a), abs(b)), abs_tol)


def circular_mean(vectors: Sequence[np.ndarray]) -> float:
    """The mean direction of 2D vectors, in radians with 0 = north."""
    total_x = sum(v[0] for v in vectors)
    total_y = sum(v[1] for v in vectors)
    return math.atan2(total_y, total_x) - math.pi / 2


def low_pass_filter(
    input_value, previous_filter_state, filter_constant, time_step, lower_bound=-1, raw_value=0
):
    """One step of a first-order low-pass filter towards ``input_value``, plus ``raw_value``,
    kept in [``lower_bound``, 1]."""
    state = previous_filter_state + time_step * filter_constant * (
        input_value - previous_filter_state
    )
    return np.clip(state + raw_value, lower_bound, 1)


def comb(n: int, k: int) -> int:
    """The binomial coefficient n choose k."""
    return math.comb(n, k)


def get_bezier_curve(points):
    """The Bezier curve through control ``points`` as a function of t in [0, 1]."""
    degree = len(points) - 1

    def curve(t):
        return sum(
            comb(degree, i) * t**i * (1 - t) ** (degree - i) * points[i] for i in range(degree + 1)
        )

    return curve


def get_linear_segments_for_range(s_start: float, s_end: float, segment_size: float) -> list:
    """Offsets from ``s_start`` every ``segment_size`` up to ``s_end``."""
    count = int((s_end - s_start) / segment_size) + 1
    return [s_start + i * segment_size for i in range(count)]


def inplace_unwrap(wp_array):
    """``np.unwrap`` of angles [rad], written into ``wp_array`` itself (returned)."""
    angles = np.asarray(wp_array)
    angles[...] = np.unwrap(angles)
    return angles


def round_param_for_dt(dt: float) -> int:
    """The ``ndigits`` for ``round`` that keeps a multiple of ``dt`` exact (negative for
    whole numbers with trailing zeros: 100 -> -2)."""
    text = np.format_float_positional(dt)
    point = text.find(".")
    if point >= len(text) - 1:  # a whole number: "100."
        return 1 - point
    return len(text) - point - 1


def rounder_for_dt(dt: float):
    """A function rounding a time to ``dt``'s precision."""
    ndigits = round_param_for_dt(dt)
    return lambda value: round(value, ndigits)


def mult_quat(q1, q2) -> np.ndarray:
    """The Hamilton product of quaternions (w, x, y, z)."""
    w1, x1, y1, z1 = q1
    w2, x2, y2, z2 = q2
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def rotate_quat(quat, vect) -> np.ndarray:
    """``vect`` (3,) rotated by the unit quaternion ``quat`` (w, x, y, z)."""
    pure = np.concatenate([[0.0], np.asarray(vect, float)])
    conjugate = np.concatenate([[quat[0]], -np.asarray(quat[1:], float)])
    return mult_quat(mult_quat(quat, pure), conjugate)[1:]


@dataclass(frozen=True)
class CubicPolynomial:
    """``a + b s + c s^2 + d s^3``."""

    a: float
    b: float
    c: float
    d: float

    @classmethod
    def from_list(cls, coefficients: Sequence[float]) -> CubicPolynomial:
        return cls(*coefficients[:4])

    def eval(self, ds: float) -> float:
        return self.a + ds * (self.b + ds * (self.c + ds * self.d))
