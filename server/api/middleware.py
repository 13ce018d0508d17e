"""ASGI middleware of the API."""

from __future__ import annotations

import asyncio
import logging

__all__ = ["BodyLimit", "StopCancels"]

log = logging.getLogger("twb.server")


class StopCancels:
    """ASGI middleware: a request still running when the server stops (uvicorn cancels it after its graceful
    shutdown) is answered 503 if nothing was sent yet and logged in one line naming it, not as a traceback."""

    def __init__(self, app) -> None:  # type: ignore[no-untyped-def]
        self.app = app

    async def __call__(self, scope, receive, send):  # type: ignore[no-untyped-def]
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        started = False

        async def tracked_send(message):  # type: ignore[no-untyped-def]
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, tracked_send)
        except asyncio.CancelledError:
            log.warning("%s %s was still running when the server stopped: cancelled", scope.get("method", ""),
                        scope.get("path", ""))
            if not started:
                body = b'{"detail": "The server stopped before this request finished; retry when it is back."}'
                await send({"type": "http.response.start", "status": 503,
                            "headers": [(b"content-type", b"application/json"),
                                        (b"content-length", str(len(body)).encode())]})
                await send({"type": "http.response.body", "body": body})


class BodyLimit:
    """ASGI middleware: refuse request bodies larger than ``limit`` bytes with 413, streamed or not.

    A declared ``Content-Length`` over the limit is refused before reading; a
    chunked body is cut off at the limit (the application sees an empty end
    of body) and whatever it answers is replaced by the 413.
    """

    def __init__(self, app, limit: int) -> None:  # type: ignore[no-untyped-def]
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):  # type: ignore[no-untyped-def]
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        for name, value in scope.get("headers", []):
            if name == b"content-length" and value.isdigit() and int(value) > self.limit:
                return await _too_large(send, self.limit)
        seen, over, answered = 0, False, False

        async def limited_receive():  # type: ignore[no-untyped-def]
            nonlocal seen, over
            if over:
                return {"type": "http.request", "body": b"", "more_body": False}
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    over = True
                    return {"type": "http.request", "body": b"", "more_body": False}
            return message

        async def guarded_send(message):  # type: ignore[no-untyped-def]
            nonlocal answered
            if not over:
                return await send(message)
            if not answered:
                answered = True
                await _too_large(send, self.limit)

        await self.app(scope, limited_receive, guarded_send)
        if over and not answered:
            await _too_large(send, self.limit)


async def _too_large(send, limit: int) -> None:  # type: ignore[no-untyped-def]
    body = ('{"detail": "Request body larger than %d bytes"}' % limit).encode()
    await send({"type": "http.response.start", "status": 413,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})
