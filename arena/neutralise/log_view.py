"""An agent's log in an organiser's view: escape sequences and control characters shown as
``\\x1b``-style text (never interpreted by the terminal), and every line the agent wrote marked
``| `` so it cannot forge a header of ours."""

from __future__ import annotations

import re

_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")
AGENT_LINE = "| "


def visible(text: str) -> str:
    """``text`` with every control character (tab and newline kept) spelled out."""
    return _CONTROL.sub(lambda match: match.group().encode("unicode_escape").decode(), text)


def quoted(text: str) -> str:
    """The log as shown: control characters visible, each line prefixed."""
    return "\n".join(AGENT_LINE + line for line in visible(text).split("\n"))
