"""Names that cannot pass for other names: no control, bidirectional-override or invisible
characters (a right-to-left override or a zero-width joiner lets ``team`` look like ``maet`` or
like another team), refused where a name enters the service."""

from __future__ import annotations

import unicodedata

from arena.errors import ParticipantError

# Format characters (Cf: bidi controls, zero-width space/joiners, BOM, soft hyphen...), line and
# paragraph separators, and every control character; plus fillers that render as nothing.
REFUSED_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn"})
INVISIBLE = frozenset({"\u115f", "\u1160", "\u3164", "\uffa0", "\u2800"})


class UnsafeName(ParticipantError, ValueError):
    """A name holding a character that can disguise it."""


def check_name(field: str, value: str) -> str:
    """``value`` unchanged, or :class:`UnsafeName` naming the first character refused."""
    for position, char in enumerate(value):
        category = unicodedata.category(char)
        if category in REFUSED_CATEGORIES or char in INVISIBLE:
            code = f"U+{ord(char):04X}"
            label = unicodedata.name(char, "")
            raise UnsafeName(
                f"{field}: character {position + 1} ({f'{label}, ' if label else ''}{code}) is "
                f"{_kind(char, category)}, not allowed in a name"
            )
    return value


def _kind(char: str, category: str) -> str:
    if category == "Cc":
        return "a control character"
    if unicodedata.bidirectional(char) in BIDI_CONTROLS:
        return "a bidirectional control"
    return "an invisible or format character"


# The explicit embedding, override and isolate controls (Unicode's bidirectional classes).
BIDI_CONTROLS = frozenset({"LRE", "RLE", "LRO", "RLO", "PDF", "LRI", "RLI", "FSI", "PDI"})
