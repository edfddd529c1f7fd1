"""How the service's commands talk to the organiser, and the one place they get their consoles:
results on stdout, progress on stderr. Both come from `arena.terminal.make_console`, so that
written to a pipe or a file they carry no colour code, are never wrapped and never redraw a live
progress bar. Beside them: the error line, progress of long work and how a moment is written."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import datetime

import typer

from arena.neutralise.console import safe
from arena.terminal import make_console

# Results, messages and refusals: what `| grep`, `> file` and `| tail -n 1` read.
console = make_console()
# Progress of long work, kept out of the results.
err_console = make_console(stderr=True)
# [s] between the plain progress lines a long command writes to a pipe.
PLAIN_PROGRESS_S = 10.0


def fail(exc: Exception) -> typer.Exit:
    """A refusal as one error line (the service's message, never a traceback); exit status 1."""
    console.print(f"[red]error:[/red] {safe(getattr(exc, 'message', exc))}")
    return typer.Exit(1)


@contextmanager
def progress(what: str, unit: str) -> Iterator[Callable[[int, int], None]]:
    """Progress of a long command, told ``step(done, total)``: a bar on stderr when it is a
    terminal; piped, a plain line ``what: done/total unit`` at the first step, the last, and
    between them at most every PLAIN_PROGRESS_S (a pipe never sits silent for minutes, nor floods
    a log)."""
    if err_console.is_terminal:
        # deferred: CLI start-up time
        from rich.progress import Progress

        with Progress(console=err_console, transient=True) as bar:
            task = bar.add_task(what, total=None)
            yield lambda done, total: bar.update(task, completed=done, total=total)
        return
    said = -math.inf

    def line(done: int, total: int) -> None:
        nonlocal said
        if done == total or time.monotonic() - said >= PLAIN_PROGRESS_S:
            said = time.monotonic()
            err_console.print(
                f"{what}: {done}/{total} {unit}", markup=False, highlight=False, soft_wrap=True
            )

    yield line


def moment_text(moment: datetime | None) -> str:
    """A stored moment as every command writes it."""
    return "-" if moment is None else f"{moment:%Y-%m-%d %H:%M:%S} UTC"
