"""Text from an agent made storable on every database and in every UTF-8 file.

PostgreSQL refuses a NUL character in ``text`` and ``\\u0000`` in ``jsonb`` (psycopg
``DataError``), and no database driver encodes a lone surrogate (a JSON ``"\\ud800"``) as UTF-8.
One such byte in an agent's output failed the recording, the scenario was re-simulated and the
submission failed without counting towards the quota: free evaluations on the hidden set. Both
are replaced by U+FFFD, the replacement character, before anything is stored. The same lone
surrogate crashed `arena evaluate` writing the episode's log file.
"""

from __future__ import annotations

from typing import Any

REPLACEMENT = "\ufffd"
# Beyond this the structure is ours by construction: deeper values are cut, not walked.
MAX_DEPTH = 16


def storable_text(text: str) -> str:
    """``text`` with NULs and lone surrogates replaced by U+FFFD."""
    if "\0" in text:
        text = text.replace("\0", REPLACEMENT)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        text = text.encode("utf-8", "surrogatepass").decode("utf-8", "replace")
    return text


def storable_json(value: Any, depth: int = 0) -> Any:
    """A JSON-like value whose every string (keys too) is :func:`storable_text`."""
    if isinstance(value, str):
        return storable_text(value)
    if depth >= MAX_DEPTH:
        return REPLACEMENT
    if isinstance(value, dict):
        return {storable_text(str(k)): storable_json(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [storable_json(v, depth + 1) for v in value]
    return value
