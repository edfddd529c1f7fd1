"""The part of gym 0.21 that Driving SMARTS 2022 agents and wrappers use: ``Env``, ``Wrapper`` and
its observation / action / reward kinds, ``Space`` and ``spaces``, ``logger``. gym's step API of
that era: ``step(action) -> (observation, reward, done, info)``, ``reset() -> observation``.

A submission that lists ``gym`` in its requirements gets the real package instead (its
dependency folder comes first on ``sys.path``).
"""

from __future__ import annotations

from gym import logger, spaces
from gym.core import ActionWrapper, Env, GoalEnv, ObservationWrapper, RewardWrapper, Wrapper
from gym.error import Error
from gym.spaces import Space

__version__ = "0.21.0+arena"

__all__ = [
    "ActionWrapper",
    "Env",
    "Error",
    "GoalEnv",
    "ObservationWrapper",
    "RewardWrapper",
    "Space",
    "Wrapper",
    "logger",
    "make",
    "spaces",
]


def make(*args, **kwargs):
    raise Error(
        "gym.make is not available in a Driving Arena sandbox: the evaluator runs the "
        "environment and passes your Policy the observations"
    )
