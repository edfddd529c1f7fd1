"""`arena submission` and `arena sandbox` commands."""

from __future__ import annotations

import typer

submission_app = typer.Typer(no_args_is_help=True)
sandbox_app = typer.Typer(no_args_is_help=True)
