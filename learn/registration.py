"""Registers ``arena/DrivingArena-v0`` with Gymnasium, on import.

The installed package's start-up hook (``learn/gymnasium_hook.py``) imports this module as soon as
Gymnasium's registry loads; without the hook, the id's ``module:`` prefix imports it:
``gymnasium.make("learn.registration:arena/DrivingArena-v0")``.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

ENV_ID = "arena/DrivingArena-v0"


def register_envs() -> None:
    """Register the environment (idempotent)."""
    if ENV_ID not in registry:
        register(id=ENV_ID, entry_point="learn.gym_env:DrivingArenaEnv")


register_envs()
