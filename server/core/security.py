"""Bearer tokens: generated at random, stored only as SHA-256 hashes.

Tokens carry 256 bits of entropy, so a fast hash is enough (no password
stretching needed) and lookups stay a single indexed query.
"""

from __future__ import annotations

import hashlib
import secrets
import threading
from dataclasses import dataclass
from typing import Callable, Optional

__all__ = ["AuthCache", "Principal", "hash_token", "new_token"]

TOKEN_PREFIX = "twb_"


def new_token() -> str:
    """A fresh random token (``twb_`` + 43 URL-safe characters)."""
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    """Hex SHA-256 of ``token``: what the database stores."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class Principal:
    """Who a request comes from: the user behind the token and the token's kind."""

    id: int
    name: str
    is_admin: bool
    kind: str  # user, admin or agent


class AuthCache:
    """Token hash -> :class:`Principal`, loaded from the store once per token.

    Tokens are never edited, only added, so entries never go stale; the
    cache saves a database round trip (and a worker-thread hop) per request.
    """

    def __init__(self, load: Callable[[str], Optional[Principal]], max_entries: int = 10_000) -> None:
        self._load = load
        self._cache: dict[str, Principal] = {}
        self._lock = threading.Lock()
        self._max = max_entries

    def cached(self, token: str) -> Optional[Principal]:
        return self._cache.get(hash_token(token))

    def load(self, token: str) -> Optional[Principal]:
        """Look the token up in the store (blocking) and remember it if valid."""
        h = hash_token(token)
        who = self._load(h)
        if who is not None:
            with self._lock:
                if len(self._cache) >= self._max:
                    self._cache.clear()
                self._cache[h] = who
        return who
