"""Settings for a test: the real groups, with the fields a test needs changed
(:mod:`arena.settings_changes`), and what each layer takes of them."""

from __future__ import annotations

from typing import Any

from arena.config import Settings
from arena.settings_changes import env_only, with_fields


def sandbox_args(settings: Settings) -> dict[str, Any]:
    """What the sandbox layer takes (``evaluator.sandbox.start``, ``run_scenario``, ``train``):
    the sandbox group and the data folder that owns the sandboxes."""
    return {"config": settings.sandbox, "data_dir": settings.storage.resolved_data_dir}


def evaluate_args(settings: Settings) -> dict[str, Any]:
    """What ``evaluator.runner.evaluate`` takes of the settings: the intake's limits and the
    sandbox layer's."""
    return {"intake": settings.intake, **sandbox_args(settings)}


__all__ = ["env_only", "evaluate_args", "sandbox_args", "with_fields"]
