"""SMARTS core types an agent reads, and SMARTS's seeding helpers (``smarts.core.seed``,
``current_seed``, ``gen_id``)."""

import random
import uuid

import numpy as np

_seed = None


def current_seed():
    """The seed :func:`seed` was last given (None before)."""
    return _seed


def seed(a) -> None:
    """Seed Python's and numpy's global random generators."""
    global _seed
    _seed = a
    random.seed(a)
    np.random.seed(a)


def gen_id() -> str:
    """An 8-hex-digit id from Python's random generator (repeatable after :func:`seed`)."""
    return uuid.UUID(int=random.getrandbits(128)).hex[:8]
