"""Registers ``arena/DrivingArena-v0`` with Gymnasium.

``pyproject.toml`` names :func:`register_envs` under the ``gymnasium.envs`` entry point, the
plugin hook of Gymnasium before 1.0. Gymnasium 1.x no longer reads that hook, so there use
``gymnasium.make("learn.registration:arena/DrivingArena-v0", ...)`` (the ``module:`` prefix
imports this module first) or ``import learn.registration``.
"""

from __future__ import annotations

ENV_ID = "arena/DrivingArena-v0"


def register_envs() -> None:
    """Register the environment (idempotent)."""
    from gymnasium.envs.registration import register, registry

    if ENV_ID not in registry:
        register(id=ENV_ID, entry_point="learn.gym_env:DrivingArenaEnv")


register_envs()
