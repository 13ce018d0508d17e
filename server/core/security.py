"""Bearer tokens: generated at random, stored only as SHA-256 hashes.

Tokens carry 256 bits of entropy, so a fast hash is enough (no password
stretching needed) and lookups stay a single indexed query.
"""

from __future__ import annotations

import hashlib
import secrets

__all__ = ["hash_token", "new_token"]

TOKEN_PREFIX = "twb_"


def new_token() -> str:
    """A fresh random token (``twb_`` + 43 URL-safe characters)."""
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    """Hex SHA-256 of ``token``: what the database stores."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()
