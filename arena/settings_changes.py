"""Settings with some fields changed, validated as ``Settings()`` validates them: what the tests
and the benchmarks configure a service or an evaluation with."""

from __future__ import annotations

from typing import Any

from arena.config import Settings


def with_fields(settings: Settings, **groups: dict[str, Any]) -> Settings:
    """`settings` with fields of its groups changed, validated as `Settings()` validates them:
    ``with_fields(s, sandbox={"step_timeout_s": 5.0}, storage={"data_dir": d})``.

    A group or field that does not exist fails (``model_copy(update=...)`` would add it
    silently and the test would run with the default).
    """
    changed = {}
    for name, fields in groups.items():
        if name not in Settings.model_fields:
            raise TypeError(f"Settings has no group {name!r}")
        group = getattr(settings, name)
        kind = type(group)
        unknown = set(fields) - set(kind.model_fields)
        if unknown:
            raise TypeError(f"{kind.__name__} has no field {', '.join(sorted(unknown))}")
        # model_validate, not the constructor: the group is not read from the environment again.
        changed[name] = kind.model_validate(group.model_dump() | fields)
    return settings.model_copy(update=changed)


def env_only(**groups: dict[str, Any]) -> Settings:
    """Settings from the environment only (no `.env` of the working folder), changed."""
    return with_fields(Settings.load(env_file=None), **groups)
