"""The organisers' secret seed, given as a number or as a passphrase.

A passphrase is turned into the integer every build uses by sha256 (first 8 bytes), so the same
text always builds the same suite. What keeps the hidden suite hidden is that nobody can guess the
secret: a small number or a dictionary word can be found by building suites until one matches a
leaked scenario. Pick at least 128 random bits, e.g.
``python3 -c 'import secrets; print(secrets.token_urlsafe(24))'``, and keep it with the other
deployment secrets.
"""

from __future__ import annotations

import hashlib

from arena.errors import ArenaError

_DOMAIN = "driving-arena/secret-seed/"


class SeedError(ArenaError, ValueError):
    """An empty seed."""


def parse_seed(text: str | int) -> int:
    """``text`` as the integer seed: itself when it is a non-negative integer, else derived from
    the passphrase."""
    if isinstance(text, int):
        if text < 0:
            raise SeedError("a seed is a non-negative integer or a passphrase")
        return text
    stripped = text.strip()
    if not stripped:
        raise SeedError("the seed is empty: give a number or a passphrase")
    if stripped.isdigit():
        return int(stripped)
    digest = hashlib.sha256((_DOMAIN + stripped).encode()).digest()
    return int.from_bytes(digest[:8], "big")
