"""CSV cells a spreadsheet shows as text: a cell starting like a formula (``=``, ``+``, ``-``,
``@``, tab, carriage return) gets a leading apostrophe, as OWASP recommends, so
``=HYPERLINK(...)`` in a method name is never evaluated by whoever opens the export."""

from __future__ import annotations

import csv
from collections.abc import Iterable
from typing import Any

FORMULA_PREFIXES = ("=", "+", "-", "@", "\t", "\r")


def cell(value: Any) -> Any:
    """A cell value safe to open: numbers (and text that is one, like ``-0.5``) unchanged,
    other text starting like a formula defused."""
    if isinstance(value, str) and value.startswith(FORMULA_PREFIXES) and not _is_number(value):
        return "'" + value
    return value


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def write_rows(handle, header: Iterable[str], rows: Iterable[Iterable[Any]]) -> None:
    """The one CSV writer of the service: every cell through :func:`cell`."""
    # RFC 4180's CRLF rows: the csv module then quotes a cell holding a lone CR too (with "\n"
    # rows it does not, and a CR in a name would start a new row in some readers).
    writer = csv.writer(handle, lineterminator="\r\n")
    writer.writerow([cell(name) for name in header])
    for row in rows:
        writer.writerow([cell(value) for value in row])
