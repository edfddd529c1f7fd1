import math

import numpy as np
from shapely.geometry import Polygon

from sim.geometry import box_corners, box_overlaps_box, boxes_overlap, wrap


def box(x, y, heading, length=4.5, width=1.8):
    return box_corners(np.array([x]), np.array([y]), np.array([heading]), length, width)


def test_side_by_side_overlap_is_detected():
    ego = box(0.0, 0.0, 0.0)[0]
    # Side swipe: centres 1.7 m apart laterally, bodies 1.8 m wide -> 0.1 m overlap.
    assert boxes_overlap(ego, box(1.0, 1.7, 0.0)).tolist() == [True]
    assert boxes_overlap(ego, box(1.0, 1.9, 0.0)).tolist() == [False]


def test_overlap_agrees_with_polygon_intersection():
    # Random rotated boxes against an exact polygon test (shapely).
    rng = np.random.default_rng(7)
    n = 400
    x, y = rng.uniform(-6, 6, n), rng.uniform(-4, 4, n)
    heading = rng.uniform(-math.pi, math.pi, n)
    others = box_corners(x, y, heading, np.full(n, 4.5), np.full(n, 1.8))
    ego = box(0.0, 0.0, 0.3)[0]
    expected = [Polygon(ego).intersects(Polygon(c)) for c in others]
    assert boxes_overlap(ego, others).tolist() == expected
    assert 50 < sum(expected) < n - 50  # both outcomes are exercised


def test_wrap_is_half_open_interval():
    assert wrap(math.pi) == math.pi
    assert wrap(-math.pi) == math.pi
    assert wrap(3 * math.pi / 2) == -math.pi / 2


def test_scalar_pair_test_agrees_with_the_array_test():
    rng = np.random.default_rng(11)
    ego = (0.0, 0.0, 0.3, 4.5, 1.8)
    corners = box_corners(*[np.array([v]) for v in ego])[0]
    for _ in range(300):
        other = (*rng.uniform(-6, 6, 2), rng.uniform(-math.pi, math.pi), 4.5, 1.8)
        theirs = box_corners(*[np.array([v]) for v in other])
        assert box_overlaps_box(ego, other) == bool(boxes_overlap(corners, theirs)[0])


def test_pairs_of_boxes_are_tested_pair_by_pair():
    # A replay's builder checks one vehicle's boxes against another's frame by frame: a[i] with
    # b[i] only, whatever the other pairs do.
    rng = np.random.default_rng(5)
    n = 400
    a = box_corners(*rng.uniform(-3, 3, (2, n)), rng.uniform(-math.pi, math.pi, n), 4.5, 1.8)
    b = box_corners(*rng.uniform(-6, 6, (2, n)), rng.uniform(-math.pi, math.pi, n),
                    rng.uniform(3.0, 12.0, n), rng.uniform(1.5, 2.6, n))  # fmt: skip
    expected = [Polygon(p).intersects(Polygon(q)) for p, q in zip(a, b, strict=True)]
    assert boxes_overlap(a, b).tolist() == expected
    assert 50 < sum(expected) < n - 50  # both outcomes are exercised
    assert boxes_overlap(a[:0], b[:0]).tolist() == []
