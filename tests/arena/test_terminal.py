"""Command output in a pipe is never cropped or wrapped at 80 columns: every Rich console of the
project comes from arena.terminal.make_console."""

from __future__ import annotations

import re
from pathlib import Path

from rich.panel import Panel
from rich.table import Table

from arena.terminal import make_console
from tests.packages import HOST

ROOT = Path(__file__).resolve().parents[2]


def test_a_panel_and_a_table_in_a_pipe_keep_their_full_text(capsys):
    console = make_console()
    assert not console.is_terminal  # pytest captures stdout: a pipe, as for `arena up | tee`
    long = "the hidden suite is built from the PUBLIC DEVELOPMENT SEED 20221128. " * 3
    url = "http://127.0.0.1:8000/submit · API docs at http://127.0.0.1:8000/docs"
    console.print(Panel.fit(f"{long}\n{url}", title="arena up"))
    table = Table("scenario", "reason")
    table.add_row("h001-cut_in-dense-some-very-long-variant-name", "x" * 150)
    console.print(table)
    out = capsys.readouterr().out
    assert long.strip() in out
    assert url in out
    assert "x" * 150 in out
    assert "…" not in out


def test_no_console_is_built_outside_make_console():
    built = []
    for package in HOST:
        for path in (ROOT / package).rglob("*.py"):
            if path == ROOT / "arena" / "terminal.py":
                continue
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"(?<![\w.])Console\(", line):
                    built.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert built == []
