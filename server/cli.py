"""`arena admin ...` and the service commands (`arena up`)."""

from __future__ import annotations

import typer

admin_app = typer.Typer(no_args_is_help=True)
service_app = typer.Typer(no_args_is_help=True)
