"""CSV cells a spreadsheet shows as text: a cell starting like a formula (``=``, ``+``, ``-``,
``@``, tab, carriage return) gets a leading apostrophe, as OWASP recommends, so
``=HYPERLINK(...)`` in a method name is never evaluated by whoever opens the export."""

from __future__ import annotations

import csv
from collections.abc import Iterable
from typing import Any

FORMULA_PREFIXES = ("=", "+", "-", "@", "\t", "\r")


def cell(value: Any) -> Any:
    """A cell value safe to open: numbers unchanged, text defused."""
    if isinstance(value, str) and value.startswith(FORMULA_PREFIXES):
        return "'" + value
    return value


def write_rows(handle, header: Iterable[str], rows: Iterable[Iterable[Any]]) -> None:
    """The one CSV writer of the service: every cell through :func:`cell`."""
    writer = csv.writer(handle)
    writer.writerow([cell(name) for name in header])
    for row in rows:
        writer.writerow([cell(value) for value in row])
