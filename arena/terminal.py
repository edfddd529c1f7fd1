"""Command output that survives pipes and logs.

On a terminal a listing is a Rich table that folds long cells instead of cutting them; piped or
redirected it is one plain tab-separated line per row (header first), never wrapped at 80
columns, so ``grep``, ``cut`` and ``awk`` work on it. ``--json`` prints the rows as a JSON list.

Every Rich console of the project comes from :func:`make_console`: Rich assumes 80 columns when
it cannot ask a terminal, and then crops panels and tables; ours lay out at :data:`PIPE_WIDTH`
(wide enough that nothing real is cut) and never wrap a printed line.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence

from rich.console import Console
from rich.table import Table

from arena.neutralise.console import plain, safe

Cell = str | int | float | None
# Columns a console lays out in when it writes to a pipe or file: a panel (Panel.fit) or table is
# as wide as its content, and its content never meets the edge.
PIPE_WIDTH = 4096


def make_console(*, stderr: bool = False) -> Console:
    """A console that neither wraps nor crops when it is not a terminal."""
    console = Console(stderr=stderr)
    if not console.is_terminal:
        console = Console(stderr=stderr, soft_wrap=True, width=PIPE_WIDTH)
    return console


def _text(value: Cell) -> str:
    """A cell as shown: no control character (team text reaches organisers' terminals), and no
    tab or newline to split the plain line it sits in."""
    return "-" if value is None else plain(value).replace("\t", " ").replace("\n", " ")


def print_rows(
    console: Console,
    columns: Sequence[str],
    rows: Sequence[Sequence[Cell]],
    *,
    title: str | None = None,
    as_json: bool = False,
    numeric: Sequence[str] = (),
) -> None:
    if as_json:
        records = [dict(zip(columns, row, strict=True)) for row in rows]
        sys.stdout.write(json.dumps(records, indent=2, default=str) + "\n")
        return
    if not console.is_terminal:
        # Written straight to the file: Rich would expand the tabs into spaces.
        lines = [f"# {_text(title)}"] if title else []
        lines += ["\t".join(_text(cell) for cell in line) for line in (columns, *rows)]
        console.file.write("\n".join(lines) + "\n")
        return
    table = Table(title=safe(title) if title else None)
    for column in columns:
        justify = "right" if column in numeric else "left"
        table.add_column(column, justify=justify, overflow="fold")
    for row in rows:
        # Cells are text, never markup: a `[/]` in a method name once crashed the listing.
        table.add_row(*(safe(_text(cell)) for cell in row))
    console.print(table)
