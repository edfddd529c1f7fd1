"""Every exception class of the project derives from ArenaError (arena/errors.py), so a command
line or a task catches ours once; the inside of the sandbox (agent_runtime) imports nothing of
ours and is exempt."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

from arena.errors import ArenaError
from tests.packages import HOST


def our_modules():
    for name in HOST:
        package = importlib.import_module(name)
        yield name
        for info in pkgutil.walk_packages(package.__path__, f"{name}."):
            yield info.name


def exception_classes():
    for module_name in our_modules():
        module = importlib.import_module(module_name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ == module_name and issubclass(cls, BaseException):
                yield f"{module_name}.{cls.__qualname__}", cls


EXCEPTIONS = dict(exception_classes())


def test_the_walk_finds_our_exceptions():
    assert "arena.errors.IntakeError" in EXCEPTIONS
    assert "server.services.errors.NotFound" in EXCEPTIONS


@pytest.mark.parametrize("name", sorted(EXCEPTIONS))
def test_every_exception_of_ours_is_an_arena_error(name):
    assert issubclass(EXCEPTIONS[name], ArenaError), f"{name} does not derive from ArenaError"
