"""`arena admin leaderboard ...`: a phase's leaderboard as CSV
(`server/services/leaderboard.py`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from server.commands.console import console, fail
from server.commands.context import AdminContext, or_fail
from server.tracks import Track

app = typer.Typer(no_args_is_help=True)


@app.command("export")
def leaderboard_export(
    track: Annotated[Track, typer.Option(help="Which track's leaderboard.")] = Track.freestyle,
    phase: Annotated[str, typer.Option(help="Which phase's leaderboard.")] = "final",
    out: Annotated[Path | None, typer.Option(help="File to write (default: stdout).")] = None,
    gap_from: Annotated[
        str | None,
        typer.Option(help="Add each entry's generalisation gap to this phase (e.g. validation)."),
    ] = None,
) -> None:
    """The leaderboard of one phase and track as CSV."""
    # deferred: CLI start-up time
    from server.services import leaderboard, phases

    ctx = AdminContext()
    with ctx.db.read_session() as session:
        or_fail(lambda: phases.get_phase(session, phase))
        board = leaderboard.compute(session, track, phase)
        if gap_from is not None:
            or_fail(lambda: phases.get_phase(session, gap_from))
            board = leaderboard.with_gap(board, leaderboard.compute(session, track, gap_from))
        text = leaderboard.to_csv(board)
    if out is None:
        typer.echo(text, nl=False)
        return
    try:
        out.write_text(text)
    except OSError as exc:
        raise fail(ValueError(f"cannot write {out}: {exc.strerror or exc}")) from None
    console.print(f"wrote {out}")
