"""Planar geometry of vehicles: angle wrapping, oriented bounding boxes and their overlap test."""

from __future__ import annotations

import math

import numpy as np

from arena import portable_math


def wrap(angle: float) -> float:
    """Wrap radians to (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a


def box_corners(
    x: np.ndarray, y: np.ndarray, heading: np.ndarray, length: np.ndarray, width: np.ndarray
) -> np.ndarray:
    """Corners (n, 4, 2) [m] of oriented rectangles centred at (x, y) [m], counter-clockwise."""
    c, s = portable_math.cos(heading), portable_math.sin(heading)
    hl, hw = np.asarray(length) / 2, np.asarray(width) / 2
    fx, fy = c * hl, s * hl  # half-length along the heading
    lx, ly = -s * hw, c * hw  # half-width to the left
    cx, cy = np.asarray(x), np.asarray(y)
    return np.stack(
        [
            np.stack([cx + fx - lx, cy + fy - ly], -1),
            np.stack([cx + fx + lx, cy + fy + ly], -1),
            np.stack([cx - fx + lx, cy - fy + ly], -1),
            np.stack([cx - fx - lx, cy - fy - ly], -1),
        ],
        -2,
    )


def boxes_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Which rectangles overlap, as (n,) booleans: ``a`` and ``b`` are corners (:func:`box_corners`)
    [m] that broadcast against each other, (4, 2) or (n, 4, 2) each: one rectangle against many, or
    rectangle ``a[i]`` against ``b[i]`` (a vehicle's boxes against another's, frame by frame).

    Separating axis theorem: two convex polygons are disjoint iff their projections are disjoint
    on one of the edge normals; rectangles have two normals each. Touching counts as overlap.
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    if a.ndim == 2:
        a, b = a[None], b[None]
    if len(a) == 0:
        return np.zeros(0, dtype=bool)
    axes = np.stack(
        [a[:, 1] - a[:, 0], a[:, 2] - a[:, 1], b[:, 1] - b[:, 0], b[:, 2] - b[:, 1]], 1
    )  # (n, 4, 2)
    # Products and one sum each, no einsum: its kernels may fuse them (FMA) on some CPUs.
    a_proj = axes[:, :, None, 0] * a[:, None, :, 0] + axes[:, :, None, 1] * a[:, None, :, 1]
    b_proj = axes[:, :, None, 0] * b[:, None, :, 0] + axes[:, :, None, 1] * b[:, None, :, 1]
    separated = (a_proj.max(-1) < b_proj.min(-1)) | (b_proj.max(-1) < a_proj.min(-1))
    return ~separated.any(-1)


def box_overlaps_box(
    a: tuple[float, float, float, float, float], b: tuple[float, float, float, float, float]
) -> bool:
    """Whether two oriented rectangles (x, y, heading, length, width) overlap (touching counts).

    Separating axis theorem on the rectangles' four edge directions, in scalar Python: for the
    one to three candidates per step this is much cheaper than array code.
    """
    ax, ay, ah, al, aw = a
    bx, by, bh, bl, bw = b
    dx, dy = bx - ax, by - ay
    ca, sa, cb, sb = math.cos(ah), math.sin(ah), math.cos(bh), math.sin(bh)
    for ux, uy in ((ca, sa), (-sa, ca), (cb, sb), (-sb, cb)):
        # Projected half extents of both boxes on the axis, against the projected centre distance.
        ra = 0.5 * (al * abs(ca * ux + sa * uy) + aw * abs(-sa * ux + ca * uy))
        rb = 0.5 * (bl * abs(cb * ux + sb * uy) + bw * abs(-sb * ux + cb * uy))
        if abs(dx * ux + dy * uy) > ra + rb:
            return False
    return True
