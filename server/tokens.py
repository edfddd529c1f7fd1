"""Team API tokens: random secrets shown once, stored only as their sha256."""

from __future__ import annotations

import hashlib
import hmac
import secrets

TOKEN_PREFIX = "arena_"


def new_token() -> str:
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def same_secret(given: str, expected: str) -> bool:
    return hmac.compare_digest(given.encode(), expected.encode())
