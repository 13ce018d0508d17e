"""Where the SDK finds the server URL and the access token.

URL: the ``url`` argument, else ``$TWB_URL``, else ``http://127.0.0.1:8000``
(where ``twb up`` listens by default).

Token, first found wins:

1. the ``token`` argument;
2. the environment variable ``TWB_TOKEN``;
3. the file ``twb up`` writes: ``$TWB_DATA_DIR/token`` if ``TWB_DATA_DIR`` is
   set, else ``./twb-data/token`` (relative to the current directory).

No token at all is allowed (``/health`` is open); other calls then raise
:class:`~client_sdk.Unauthorized` with the server's message and
:func:`missing_token_hint`: where the SDK looked and how to pass one.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

__all__ = ["DEFAULT_URL", "missing_token_hint", "resolve_token", "resolve_url", "token_file"]

DEFAULT_URL = "http://127.0.0.1:8000"


def resolve_url(url: Optional[str] = None) -> str:
    """``url``, else ``$TWB_URL``, else :data:`DEFAULT_URL`; without a trailing slash."""
    return (url or os.environ.get("TWB_URL") or DEFAULT_URL).rstrip("/")


def token_file() -> Path:
    """The token file ``twb up`` writes: ``$TWB_DATA_DIR/token`` or ``./twb-data/token``."""
    return Path(os.environ.get("TWB_DATA_DIR") or "twb-data") / "token"


def resolve_token(token: Optional[str] = None) -> Optional[str]:
    """``token``, else ``$TWB_TOKEN``, else the content of :func:`token_file`, else None."""
    if token:
        return token
    env = os.environ.get("TWB_TOKEN")
    if env:
        return env.strip()
    path = token_file()
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return text or None


def missing_token_hint() -> str:
    """Why a request went without a token, in words: where the SDK looked and how to pass one."""
    return (f"no token found: looked for the token= argument, $TWB_TOKEN and the file {token_file().resolve()}; "
            "pass Client(token=...), set TWB_TOKEN, or run where `twb up` wrote twb-data/token "
            "(or set TWB_DATA_DIR to its data directory)")
