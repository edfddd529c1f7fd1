"""Sines, cosines, arctangents and exponentials over arrays, the same on every CPU.

numpy picks the kernels of its transcendental functions at run time for the CPU's vector
extensions: on AVX-512 machines ``np.sin``, ``np.cos``, ``np.arctan2``, ``np.exp`` and others are
Intel SVML's, whose results differ from the C library's in the last bit. A record, a score or a
built suite must be the same bytes whichever worker made it (the same scenario ran on an AVX-512
machine and on an AVX2 one gave other waypoint headings, so other records and digests), so every
value that reaches one is computed here instead: the C library's functions (Python's
:mod:`math`), one element at a time. glibc computes them alike on every x86-64 CPU with FMA.
``tests/arena/test_portable_math.py`` keeps numpy's versions out of the packages whose values
reach records, scores, suites or observations.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike


def _elementwise(function: Callable[..., float], *args: ArrayLike) -> np.ndarray:
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in args))
    flat = [a.ravel().tolist() for a in arrays]
    values = np.fromiter(map(function, *flat), np.float64, arrays[0].size)
    return values.reshape(arrays[0].shape)


def sin(angle: ArrayLike) -> np.ndarray:
    return _elementwise(math.sin, angle)


def cos(angle: ArrayLike) -> np.ndarray:
    return _elementwise(math.cos, angle)


def arctan2(y: ArrayLike, x: ArrayLike) -> np.ndarray:
    return _elementwise(math.atan2, y, x)


def exp(x: ArrayLike) -> np.ndarray:
    return _elementwise(math.exp, x)
