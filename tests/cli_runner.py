"""Typer's test runner with each app's click command built once per process.

``typer.testing.CliRunner.invoke`` rebuilds the whole click tree of the app on every call (about
27 ms for the `arena` command), which the fast tier's 200-odd command invocations paid each time.
The tree is a pure function of the app's registered commands, so it is built once; the runner is
otherwise Typer's own (``typer.testing`` builds the tree through its alias of
``typer.main.get_command``, which is swapped for the cached one during the call)."""

from __future__ import annotations

import functools
from typing import Any
from unittest import mock

import click.testing
import typer
import typer.testing


@functools.cache
def _command(app: typer.Typer) -> click.Command:
    return typer.main.get_command(app)


class CliRunner(typer.testing.CliRunner):
    def invoke(self, app: typer.Typer, *args: Any, **kwargs: Any) -> click.testing.Result:
        with mock.patch.object(typer.testing, "_get_command", _command):
            return super().invoke(app, *args, **kwargs)
