"""The event loop of the long-running commands (``twb up``, ``twb server``, ``twb agent``)."""

from __future__ import annotations

import asyncio
from typing import Any, Coroutine

__all__ = ["run"]


def run(main: Coroutine[Any, Any, Any]) -> None:
    """Run ``main`` to completion on uvloop when installed (a faster loop: the robots' sockets cost about
    half the CPU on it, docs/performance.md), else on asyncio's own loop."""
    try:
        import uvloop
    except ImportError:
        asyncio.run(main)
    else:
        uvloop.run(main)
