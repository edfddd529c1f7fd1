"""gym 0.21's spaces with their constructors' full signatures (``Box(low, high, shape=None,
dtype=np.float32, seed=None)``, ``Discrete(n, seed=None)``, ``MultiBinary(n, seed=None)``,
``MultiDiscrete(nvec, dtype=np.int64, seed=None)``, ``Tuple(spaces, seed=None)``,
``Dict(spaces=None, seed=None, **spaces_kwargs)``), enough for agents that declare, sample or
check them."""

from __future__ import annotations

from collections import OrderedDict

import numpy as np


class Space:
    def __init__(self, shape=None, dtype=None, seed=None) -> None:
        self._shape = None if shape is None else tuple(shape)
        self.dtype = None if dtype is None else np.dtype(dtype)
        self._np_random = None
        if seed is not None:
            self.seed(seed)

    @property
    def shape(self):
        return self._shape

    @property
    def np_random(self) -> np.random.Generator:
        if self._np_random is None:
            self.seed()
        return self._np_random

    def seed(self, seed=None) -> list:
        self._np_random = np.random.default_rng(seed)
        return [seed]

    def sample(self):
        raise NotImplementedError

    def contains(self, x) -> bool:
        raise NotImplementedError

    def __contains__(self, x) -> bool:
        return self.contains(x)


class Box(Space):
    def __init__(self, low, high, shape=None, dtype=np.float32, seed=None) -> None:
        dtype = np.dtype(dtype)
        if shape is None:
            shape = np.broadcast(np.asarray(low), np.asarray(high)).shape
        shape = tuple(shape)
        self.low = np.full(shape, low, dtype=dtype) if np.isscalar(low) else np.asarray(low, dtype)
        self.high = (
            np.full(shape, high, dtype=dtype) if np.isscalar(high) else np.asarray(high, dtype)
        )
        super().__init__(shape, dtype, seed)

    def sample(self) -> np.ndarray:
        low = np.where(np.isfinite(self.low), self.low, -1.0)
        high = np.where(np.isfinite(self.high), self.high, 1.0)
        if self.dtype.kind in "iu":
            return self.np_random.integers(low, high, endpoint=True).astype(self.dtype)
        return self.np_random.uniform(low, high).astype(self.dtype)

    @property
    def bounded_below(self) -> np.ndarray:
        return -np.inf < self.low

    @property
    def bounded_above(self) -> np.ndarray:
        return np.inf > self.high

    def is_bounded(self, manner: str = "both") -> bool:
        below, above = bool(np.all(self.bounded_below)), bool(np.all(self.bounded_above))
        if manner not in ("both", "below", "above"):
            raise ValueError("manner is not in {'below', 'above', 'both'}")
        return {"both": below and above, "below": below, "above": above}[manner]

    def contains(self, x) -> bool:
        x = np.asarray(x)
        return x.shape == self.shape and bool(np.all(x >= self.low) and np.all(x <= self.high))

    def __repr__(self) -> str:
        return f"Box({self.low.min()}, {self.high.max()}, {self.shape}, {self.dtype})"


class Discrete(Space):
    def __init__(self, n: int, seed=None, start: int = 0) -> None:
        self.n = int(n)
        self.start = int(start)
        super().__init__((), np.int64, seed)

    def sample(self) -> int:
        return int(self.start + self.np_random.integers(self.n))

    def contains(self, x) -> bool:
        try:
            value = int(x)
        except (TypeError, ValueError):
            return False
        return value == x and self.start <= value < self.start + self.n

    def __repr__(self) -> str:
        return f"Discrete({self.n})"


class MultiBinary(Space):
    def __init__(self, n, seed=None) -> None:
        self.n = n
        super().__init__((n,) if np.isscalar(n) else tuple(n), np.int8, seed)

    def sample(self) -> np.ndarray:
        return self.np_random.integers(0, 2, size=self.shape).astype(self.dtype)

    def contains(self, x) -> bool:
        x = np.asarray(x)
        return x.shape == self.shape and bool(np.all((x == 0) | (x == 1)))


class MultiDiscrete(Space):
    def __init__(self, nvec, dtype=np.int64, seed=None) -> None:
        self.nvec = np.asarray(nvec, dtype=dtype)
        super().__init__(self.nvec.shape, dtype, seed)

    def sample(self) -> np.ndarray:
        return (self.np_random.random(self.nvec.shape) * self.nvec).astype(self.dtype)

    def contains(self, x) -> bool:
        x = np.asarray(x)
        return x.shape == self.shape and bool(np.all((x >= 0) & (x < self.nvec)))


class Tuple(Space):
    def __init__(self, spaces, seed=None) -> None:
        self.spaces = tuple(spaces)
        super().__init__(None, None, seed)

    def sample(self) -> tuple:
        return tuple(space.sample() for space in self.spaces)

    def contains(self, x) -> bool:
        return (
            isinstance(x, tuple)
            and len(x) == len(self.spaces)
            and all(s.contains(v) for s, v in zip(self.spaces, x, strict=True))
        )

    def __getitem__(self, index: int) -> Space:
        return self.spaces[index]

    def __len__(self) -> int:
        return len(self.spaces)


class Dict(Space):
    """gym 0.21's: a plain dict's keys are sorted (an ``OrderedDict`` or a list of pairs keeps
    its order), so flattening and networks see the keys in one order."""

    def __init__(self, spaces=None, seed=None, **spaces_kwargs) -> None:
        if spaces is None:
            spaces = spaces_kwargs
        if isinstance(spaces, dict) and not isinstance(spaces, OrderedDict):
            spaces = sorted(spaces.items())
        self.spaces = OrderedDict(spaces)
        super().__init__(None, None, seed)

    def sample(self) -> OrderedDict:
        return OrderedDict((k, space.sample()) for k, space in self.spaces.items())

    def contains(self, x) -> bool:
        return (
            isinstance(x, dict)
            and x.keys() == self.spaces.keys()
            and all(space.contains(x[k]) for k, space in self.spaces.items())
        )

    def __getitem__(self, key: str) -> Space:
        return self.spaces[key]

    def __setitem__(self, key: str, value: Space) -> None:
        self.spaces[key] = value

    def __iter__(self):
        return iter(self.spaces)

    def __len__(self) -> int:
        return len(self.spaces)

    def keys(self):
        return self.spaces.keys()

    def values(self):
        return self.spaces.values()

    def items(self):
        return self.spaces.items()
