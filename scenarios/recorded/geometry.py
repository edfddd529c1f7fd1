"""Oriented bounding-box overlap, vectorised over frames (separating axis test)."""

from __future__ import annotations

import numpy as np

from arena import portable_math


def corners(boxes: np.ndarray) -> np.ndarray:
    """(n, 4, 2) corners of (n, 5) boxes [x, y, heading, length, width]."""
    x, y, h, length, width = boxes.T
    c, s = portable_math.cos(h), portable_math.sin(h)
    dx = np.stack([length, length, -length, -length], axis=1) / 2
    dy = np.stack([width, -width, -width, width], axis=1) / 2
    return np.stack(
        [
            x[:, None] + c[:, None] * dx - s[:, None] * dy,
            y[:, None] + s[:, None] * dx + c[:, None] * dy,
        ],
        axis=2,
    )


def boxes_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) whether box ``a[i]`` overlaps ``b[i]``; both (n, 5) [x, y, heading, length, width]."""
    ca, cb = corners(a), corners(b)
    overlap = np.ones(len(a), dtype=bool)
    for heading in (a[:, 2], a[:, 2] + np.pi / 2, b[:, 2], b[:, 2] + np.pi / 2):
        axis = np.stack([portable_math.cos(heading), portable_math.sin(heading)], axis=1)[
            :, None, :
        ]
        pa = (ca * axis).sum(axis=2)
        pb = (cb * axis).sum(axis=2)
        overlap &= (pa.max(axis=1) >= pb.min(axis=1)) & (pb.max(axis=1) >= pa.min(axis=1))
    return overlap
