"""Team text on a terminal (an organiser's, a participant's running `arena evaluate`): Rich
markup escaped (a ``[/]`` in a method name would otherwise crash the table or restyle it),
control characters (escape sequences that set the window title or write the clipboard) replaced
by a visible ``?``, and lone surrogates (no terminal encoding has them: printing one crashed the
command) by U+FFFD."""

from __future__ import annotations

import re

from rich.markup import escape

from arena.neutralise.storable import storable_text

_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def plain(value: object) -> str:
    """``value`` as text with no control character and no lone surrogate."""
    return storable_text(_CONTROL.sub("?", str(value)))


def safe(value: object) -> str:
    """``value`` ready to embed in a Rich markup string or table cell."""
    return escape(plain(value))
