"""Bearer tokens: generated at random, stored only as SHA-256 hashes.

Tokens carry 256 bits of entropy, so a fast hash is enough (no password
stretching needed) and lookups stay a single indexed query.
"""

from __future__ import annotations

import secrets
import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional

from contract.auth import token_hash

__all__ = ["AuthCache", "FailedTokens", "Principal", "hash_token", "new_token"]

TOKEN_PREFIX = "twb_"


def new_token() -> str:
    """A fresh random token (``twb_`` + 43 URL-safe characters)."""
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    """Hex SHA-256 of ``token``: what the database stores (and what robots' control keys derive from)."""
    return token_hash(token)


@dataclass(frozen=True)
class Principal:
    """Who a request comes from: the user behind the token, the token's kind and the token itself (its row)."""

    id: int
    name: str
    is_admin: bool
    kind: str  # user, admin or agent
    token_id: Optional[int] = None
    token_hash: str = ""


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


class FailedTokens:
    """Failed token attempts per client: over ``limit`` in ``window_s`` seconds, the client waits.

    Guessing a 256-bit token is hopeless anyway; this keeps a flood of
    guesses from costing a database lookup each (and says so: 429).
    Thread-safe; ``clock`` is injectable for tests.
    """

    def __init__(self, limit: int = 30, window_s: float = 60.0, clock: Callable[[], float] = time.monotonic,
                 max_clients: int = 10_000) -> None:
        self.limit, self.window_s = limit, window_s
        self._clock = clock
        self._failures: dict[str, list[float]] = {}
        self._lock = threading.Lock()
        self._max = max_clients

    def _recent(self, client: str, now: float) -> list[float]:
        times = [t for t in self._failures.get(client, []) if now - t < self.window_s]
        if times:
            self._failures[client] = times
        else:
            self._failures.pop(client, None)
        return times

    def wait_s(self, client: str) -> float:
        """Seconds ``client`` must wait before its next token is looked up (0: go ahead)."""
        with self._lock:
            now = self._clock()
            times = self._recent(client, now)
            if len(times) < self.limit:
                return 0.0
            return max(times[-self.limit] + self.window_s - now, 0.001)

    def failed(self, client: str) -> None:
        """``client`` presented a token that does not exist."""
        with self._lock:
            now = self._clock()
            if client not in self._failures and len(self._failures) >= self._max:
                self._failures.clear()
            self._failures.setdefault(client, []).append(now)
            del self._failures[client][:-self.limit]
