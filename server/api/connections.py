"""The API's HTTP connections: the deadlines and caps uvicorn does not have (docs/security.md, "HTTP connections").

uvicorn closes a keep-alive connection that stays idle after a response
(``timeout_keep_alive``), but nothing bounds how long a request's head may
take to arrive, how large it may grow, how long a body may pause, or how many
connections are open: 10,000 connections that each sent half a request were
held for ever, and at ~20,000 the process ran out of file descriptors — the
API refused ``/health`` and the robots of ``twb up`` (same process) could not
greet their own testbed.  :func:`guarded_protocol` gives uvicorn its
httptools protocol with:

- **a head deadline**: a request's line and headers must be complete
  ``header_timeout_s`` after a new connection opens, or after the first byte
  of a following request on a kept-alive one (then ``408`` and close);
- **a head size**: more than ``max_header_bytes`` of an unfinished head is
  ``431`` and close (httptools itself buffers a header of any size);
- **a body pause**: a request body that stops arriving for ``body_timeout_s``
  while the application waits for it closes the connection (the application
  sees ``http.disconnect``); a body the application does not read yet (flow
  control) does not count;
- **connection caps**: at most ``max_per_peer`` connections from one IP
  address (more are answered ``503`` and closed at once), and at most
  ``max_connections`` in all; when full, the connection idle longest without
  a request in progress is closed for the newcomer, and only when every
  connection has a request in progress is the newcomer refused (``503``).

Responses under way (``/api/v1/events`` streams, large downloads) are never
cut by these deadlines.  :func:`connection_budget` keeps ``max_connections``
within the process's open-file limit, leaving the robots' own connection
budgets and the server's other descriptors room.
"""

from __future__ import annotations

import asyncio
import resource
from collections import Counter
from dataclasses import dataclass
from typing import Any, ClassVar, Optional

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

__all__ = ["ConnectionBook", "HttpLimits", "connection_budget", "guarded_protocol", "raise_open_files_limit"]

#: descriptors kept free for everything but connections: the database, worker and sandbox pipes, logs, listeners
BASE_RESERVE = 256


@dataclass(frozen=True)
class HttpLimits:
    """Limits of the API's HTTP connections; times in wall seconds (``TWB_HTTP_*`` settings, docs/server.md)."""

    header_timeout_s: float = 10.0
    body_timeout_s: float = 30.0
    max_header_bytes: int = 64 << 10
    max_connections: int = 2048
    max_per_peer: int = 256

    def __post_init__(self) -> None:
        for name in ("header_timeout_s", "body_timeout_s"):
            if not getattr(self, name) > 0:  # also refuses NaN
                raise ValueError(f"`{name}` must be > 0 seconds, got {getattr(self, name)}")
        for name in ("max_header_bytes", "max_connections", "max_per_peer"):
            if getattr(self, name) < 1:
                raise ValueError(f"`{name}` must be >= 1, got {getattr(self, name)}")


class ConnectionBook:
    """The open connections of one server: counted per peer, the idle ones (no request in progress) in
    order of idleness, and how many were refused, evicted or closed by a deadline."""

    def __init__(self, limits: HttpLimits) -> None:
        self.limits = limits
        self.open = 0
        self.per_peer: Counter[str] = Counter()
        self.idle: dict["GuardedHttp", None] = {}  # insertion order: idle longest first
        self.refused = 0
        self.evicted = 0
        self.timed_out = 0

    def admit(self, conn: "GuardedHttp") -> Optional[str]:
        """Count ``conn`` in, or say why it gets no place (and count the refusal)."""
        if self.per_peer[conn.peer] >= self.limits.max_per_peer:
            self.refused += 1
            return f"too many connections from {conn.peer} (at most {self.limits.max_per_peer})"
        if self.open >= self.limits.max_connections:
            oldest = next(iter(self.idle), None)
            if oldest is None:
                self.refused += 1
                return f"too many connections (at most {self.limits.max_connections})"
            self.evicted += 1
            oldest.drop()  # counted out at once; its transport closes
        self.open += 1
        self.per_peer[conn.peer] += 1
        return None

    def leave(self, conn: "GuardedHttp") -> None:
        self.idle.pop(conn, None)
        self.open -= 1
        self.per_peer[conn.peer] -= 1
        if self.per_peer[conn.peer] <= 0:
            del self.per_peer[conn.peer]


def guarded_protocol(limits: HttpLimits) -> type["GuardedHttp"]:
    """A uvicorn HTTP protocol class (``uvicorn.Config(http=...)``) with ``limits``, and a book of its own."""
    return type("GuardedHttp", (GuardedHttp,), {"book": ConnectionBook(limits)})


class GuardedHttp(HttpToolsProtocol):
    """uvicorn's httptools protocol with the deadlines and caps of the module docstring."""

    book: ClassVar[ConnectionBook]

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.peer = ""
        self._refused = False  # never handed to uvicorn's side
        self._counted = False  # in the book
        self._head_open = False  # a request's head began and is not complete
        self._body_open = False  # its head is complete, its body is not
        self._head_bytes = 0
        self._deadline = 0.0
        self._timer: Optional[asyncio.TimerHandle] = None

    # ------------------------------------------------------------------ connection

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        peer = transport.get_extra_info("peername")
        self.peer = str(peer[0]) if isinstance(peer, tuple) and peer else str(peer or "")
        why = self.book.admit(self)
        if why is not None:
            self._refused = True
            transport.write(_response(503, why, retry_after=True))
            transport.close()
            return
        self._counted = True
        super().connection_made(transport)
        self._refresh()
        self._arm(self.book.limits.header_timeout_s)  # the first request's head must come in time

    def connection_lost(self, exc: Optional[Exception]) -> None:
        if self._refused:
            return
        if self._counted:
            self._counted = False
            self.book.leave(self)
        self._disarm()
        super().connection_lost(exc)

    def drop(self) -> None:
        """Close this connection (no request in progress) for a newcomer: counted out now."""
        if self._counted:
            self._counted = False
            self.book.leave(self)
        self._disarm()
        self.transport.close()

    def _refresh(self) -> None:
        """Keep the book's idle connections (no request in progress) in order of idleness."""
        idle = self._counted and not self._body_open and (self.cycle is None or self.cycle.response_complete)
        if not idle:
            self.book.idle.pop(self, None)
        elif self not in self.book.idle:
            self.book.idle[self] = None

    # ------------------------------------------------------------------ reading

    def data_received(self, data: bytes) -> None:
        if self._refused:
            return
        if self._body_open:
            self._deadline = self.loop.time() + self.book.limits.body_timeout_s
        else:
            self._head_bytes += len(data)
        super().data_received(data)
        if self._head_open and self._head_bytes > self.book.limits.max_header_bytes \
                and not self.transport.is_closing():
            self._close_with(431, f"request head larger than {self.book.limits.max_header_bytes} bytes")

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._head_open = True
        if self.cycle is not None:  # a following request on a kept-alive connection: from its first byte
            self._arm(self.book.limits.header_timeout_s)

    def on_headers_complete(self) -> None:
        super().on_headers_complete()
        self._head_open, self._body_open, self._head_bytes = False, True, 0
        self._refresh()
        self._arm(self.book.limits.body_timeout_s)

    def on_message_complete(self) -> None:
        super().on_message_complete()
        self._body_open = False
        self._refresh()
        if not self._head_open:
            self._disarm()

    def on_response_complete(self) -> None:
        super().on_response_complete()  # arms uvicorn's keep-alive timeout, or starts a pipelined request
        self._refresh()

    # ------------------------------------------------------------------ deadlines

    def _arm(self, seconds: float) -> None:
        self._deadline = self.loop.time() + seconds
        if self._timer is None:
            self._timer = self.loop.call_at(self._deadline, self._check)

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _check(self) -> None:
        self._timer = None
        if not self._counted or self.transport.is_closing():
            return
        now = self.loop.time()
        if self._head_open or (self.cycle is None and not self._body_open):
            waiting = "head"  # a request's head, or a new connection's first request
        elif self._body_open:
            waiting = "body"
            if (self.flow is not None and self.flow.read_paused) or getattr(self.cycle, "waiting_for_100_continue", False):
                # the application has not read it yet (or not asked for it: the client waits for 100 Continue)
                self._deadline = max(self._deadline, now + self.book.limits.body_timeout_s)
        else:
            return  # between requests (uvicorn's keep-alive timeout), or the application answers
        if now < self._deadline:
            self._timer = self.loop.call_at(self._deadline, self._check)
            return
        self.book.timed_out += 1
        if waiting == "body":
            self.transport.close()  # the application waits for the body: it sees http.disconnect
        else:
            self._close_with(408, f"request head not complete within {self.book.limits.header_timeout_s:g} s")

    def _close_with(self, status: int, detail: str) -> None:
        self._disarm()
        if not self.transport.is_closing():
            self.transport.write(_response(status, detail))
            self.transport.close()


def _response(status: int, detail: str, retry_after: bool = False) -> bytes:
    """A whole HTTP/1.1 answer with the API's error body (``{"detail": ...}``), closing the connection."""
    import json
    from http import HTTPStatus

    body = json.dumps({"detail": detail}).encode()
    head = [f"HTTP/1.1 {status} {HTTPStatus(status).phrase}", "content-type: application/json",
            f"content-length: {len(body)}", "connection: close"]
    if retry_after:
        head.append("retry-after: 1")
    return ("\r\n".join(head) + "\r\n\r\n").encode() + body


# ---------------------------------------------------------------------- file descriptors


def raise_open_files_limit(wanted: int = 1 << 16) -> int:
    """Raise this process's soft open-file limit toward its hard limit (at most ``wanted``); the soft
    limit now.  Many systems start processes at 1024 with a hard limit far above."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(hard, wanted)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    return soft


def connection_budget(wanted: int, robot_descriptors: int, open_files: Optional[int] = None) -> int:
    """How many HTTP connections the API may hold: ``wanted``, but no more than leaves free the robots'
    own connection budgets (``robot_descriptors``: the robots in this process, at most half of the limit)
    and :data:`BASE_RESERVE` descriptors for the rest of the server; at least 16."""
    if open_files is None:
        open_files = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
        if open_files == resource.RLIM_INFINITY:
            open_files = 1 << 20
    reserved = BASE_RESERVE + min(robot_descriptors, open_files // 2)
    return max(16, min(wanted, open_files - reserved))
