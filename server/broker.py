"""In-process publish/subscribe of testbed events for the live stream (SSE).

Publishers may be on the event loop or in worker threads; each subscriber has
a bounded queue and a slow subscriber loses its oldest events, never blocks
the testbed.
"""

from __future__ import annotations

import asyncio
import json
import threading
from typing import Any, AsyncIterator, Callable, Optional

__all__ = ["EventBroker"]


View = Callable[[dict[str, Any]], Optional[dict[str, Any]]]


class _Subscriber:
    def __init__(self, view: View, size: int) -> None:
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=size)
        self.view = view
        self.dropped = 0

    def put(self, event: dict[str, Any]) -> None:
        shown = self.view(event)
        if shown is None:
            return
        event = shown
        if self.queue.full():
            self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(event)


class EventBroker:
    """Fan-out of JSON-ready event dicts to subscribers, each seeing them through its own view."""

    def __init__(self, queue_size: int = 2000) -> None:
        self._subs: set[_Subscriber] = set()
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._size = queue_size
        self._lock = threading.Lock()

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        """Remember the event loop that owns the subscriber queues."""
        self._loop = loop

    def publish(self, event: dict[str, Any]) -> None:
        """Deliver ``event`` to every subscriber whose filter accepts it (thread-safe)."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            self._deliver(event)
        else:
            loop.call_soon_threadsafe(self._deliver, event)

    def _deliver(self, event: dict[str, Any]) -> None:
        with self._lock:
            subs = list(self._subs)
        for sub in subs:
            sub.put(event)

    async def stream(self, view: View, *, heartbeat_s: float = 15.0) -> AsyncIterator[str]:
        """Server-sent-event text for every event as ``view(event)`` shows it (None: not at all);
        a comment line as heartbeat."""
        sub = _Subscriber(view, self._size)
        with self._lock:
            self._subs.add(sub)
        try:
            yield "retry: 2000\n\n"
            while True:
                try:
                    event = await asyncio.wait_for(sub.queue.get(), heartbeat_s)
                except asyncio.TimeoutError:
                    yield ": keep-alive\n\n"
                    continue
                yield f"event: {event.get('type', 'message')}\ndata: {json.dumps(event, default=str)}\n\n"
        finally:
            with self._lock:
                self._subs.discard(sub)

    @property
    def subscribers(self) -> int:
        return len(self._subs)
