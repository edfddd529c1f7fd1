"""Registers ``arena/DrivingArena-v0`` whenever Gymnasium is imported, in any interpreter.

Gymnasium 1.x dropped the ``gymnasium.envs`` plugin entry points that used to make a package's
environments known without importing the package. To keep
``gymnasium.make("arena/DrivingArena-v0")`` working in a fresh interpreter, the installed package
ships ``driving_arena_gymnasium.pth`` (``build_backend/``), which calls :func:`install` at
start-up. That must cost nothing when Gymnasium is never used, so this module imports nothing
heavy: it only waits for Gymnasium's registry module to load, then registers our ids
(``learn.registration``).
"""

from __future__ import annotations

import importlib.util
import sys
from importlib.machinery import ModuleSpec
from types import ModuleType

REGISTRY_MODULE = "gymnasium.envs.registration"


def install() -> None:
    """Register now if Gymnasium's registry is loaded, else as soon as it is."""
    if REGISTRY_MODULE in sys.modules:
        _register()
    elif not any(isinstance(finder, _RegistryFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, _RegistryFinder())


def _register() -> None:
    # deferred: runs at every interpreter start (the .pth hook): keep it light
    from learn.registration import register_envs

    register_envs()


class _RegistryFinder:
    """Finds nothing itself: hands Gymnasium's registry module to the usual finders and wraps its
    loader so that our ids are registered right after the module has run."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> ModuleSpec | None:
        if name != REGISTRY_MODULE:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            spec.loader = _RegisterAfterLoad(spec.loader)
        return spec


class _RegisterAfterLoad:
    def __init__(self, loader) -> None:
        self._loader = loader

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self._loader.exec_module(module)
        _register()
