"""Deleting a team or a phase from the command line (`server/services/removal.py`): say what
goes with it, ask unless ``--yes``, delete, say what went."""

from __future__ import annotations

from collections.abc import Callable

import typer

from server.commands.console import console
from server.commands.context import AdminContext, or_fail


def delete_after_asking(
    name: str, yes: bool, preview: Callable[..., object], remove: Callable[..., object]
) -> None:
    """``preview(session, name)`` says what deleting ``name`` takes with it; ``remove(db, store,
    name)`` deletes it. Answered no, nothing is deleted and the exit status is 1."""
    ctx = AdminContext()
    with ctx.db.read_session() as session:
        what = or_fail(lambda: preview(session, name))
    console.print(f"this deletes {what.describe()}", markup=False, highlight=False)
    if not yes and not typer.confirm("delete for good?", default=False):
        console.print("nothing deleted")
        raise typer.Exit(1)
    done = or_fail(lambda: remove(ctx.db, ctx.store, name))
    console.print(f"deleted {done.describe()}", markup=False, highlight=False)
