"""The API's HTTP connection limits (server/api/connections.py) on a real uvicorn server over real sockets:
head deadline, head size, body pause, per-peer and total caps with the idle connection evicted, and what
they must not touch (a kept-alive client, a slow reader of a streamed answer, a large upload).

The whole testbed under ~2,000 half-open connections: tests/test_http_flood.py.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time

import pytest
import uvicorn

from server.api.connections import HttpLimits, connection_budget, guarded_protocol

HEAD = b"GET /health HTTP/1.1\r\nHost: x\r\n"  # half a request: the blank line never comes


async def app(scope, receive, send):  # type: ignore[no-untyped-def]
    """``/stream``: 20 chunks 0.1 s apart; ``/upload``: reads the body, answers its size (``/slow-upload``
    after 2 s); else ``ok``."""
    if scope["type"] != "http":
        return
    if scope["path"] in ("/upload", "/slow-upload"):
        if scope["path"] == "/slow-upload":
            await asyncio.sleep(2.0)  # longer than the body timeout before it asks for the body
        size, more = 0, True
        while more:
            msg = await receive()
            if msg["type"] == "http.disconnect":
                return
            size += len(msg.get("body", b""))
            more = msg.get("more_body", False)
        body = json.dumps({"size": size}).encode()
    elif scope["path"] == "/stream":
        await send({"type": "http.response.start", "status": 200, "headers": [(b"content-type", b"text/plain")]})
        for _ in range(20):
            await send({"type": "http.response.body", "body": b"tick\n", "more_body": True})
            await asyncio.sleep(0.1)
        await send({"type": "http.response.body", "body": b""})
        return
    else:
        body = b'{"status": "ok"}'
    await send({"type": "http.response.start", "status": 200,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})


class Served:
    def __init__(self, limits: HttpLimits) -> None:
        self.protocol = guarded_protocol(limits)
        self.book = self.protocol.book
        config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level="error", lifespan="off", ws="none",
                                http=self.protocol, timeout_keep_alive=5)
        self.server = uvicorn.Server(config)
        self.task: asyncio.Task | None = None
        self.port = 0

    async def __aenter__(self) -> "Served":
        self.task = asyncio.create_task(self.server.serve())
        while not self.server.started:
            await asyncio.sleep(0.01)
        self.port = self.server.servers[0].sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc) -> None:  # type: ignore[no-untyped-def]
        self.server.should_exit = True
        await self.task


async def connect(port: int, source: str = "127.0.0.1") -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))


async def answer(reader: asyncio.StreamReader, timeout: float = 30) -> tuple[float, bytes]:
    """(seconds until the server closed the connection, everything it sent)."""
    t0 = time.monotonic()
    data = await asyncio.wait_for(reader.read(), timeout)
    return time.monotonic() - t0, data


async def get(port: int, path: str = "/health") -> bytes:
    reader, writer = await connect(port)
    writer.write(f"GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".encode())
    data = await asyncio.wait_for(reader.read(), 30)
    writer.close()
    return data


async def test_half_sent_heads_are_closed_at_the_head_deadline_with_408():
    async with Served(HttpLimits(header_timeout_s=1.0)) as s:
        silent = await connect(s.port)  # sends nothing at all
        half = await connect(s.port)
        half[1].write(HEAD)
        trickle = await connect(s.port)  # a byte every 0.3 s: each byte is in time, the whole head is not
        t0 = time.monotonic()

        async def drip() -> None:
            for b in HEAD:
                if trickle[1].is_closing():
                    return
                trickle[1].write(bytes([b]))
                await asyncio.sleep(0.3)

        dripping = asyncio.create_task(drip())
        (t_silent, a), (t_half, b), (t_trickle, c) = await asyncio.gather(answer(silent[0]), answer(half[0]),
                                                                          answer(trickle[0]))
        dripping.cancel()
        for t in (t_silent, t_half, t_trickle):
            assert 0.9 <= t < 10, t  # at the deadline (1 s), not before, and closed
        for data in (a, b, c):
            assert data.startswith(b"HTTP/1.1 408 ") and b"request head not complete within 1 s" in data, data
        assert time.monotonic() - t0 < 10
        assert b'"ok"' in await get(s.port)  # the server carries on
        assert s.book.timed_out == 3 and s.book.open <= 1


async def test_a_kept_alive_connection_gets_the_head_deadline_for_each_request():
    async with Served(HttpLimits(header_timeout_s=1.0)) as s:
        reader, writer = await connect(s.port)
        for _ in range(3):  # several requests on one connection, each in time
            writer.write(b"GET /health HTTP/1.1\r\nHost: x\r\n\r\n")
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 10)
            assert head.startswith(b"HTTP/1.1 200"), head
            await asyncio.wait_for(reader.readexactly(16), 10)
            await asyncio.sleep(0.6)  # idle between requests: below uvicorn's keep-alive (5 s)
        writer.write(HEAD)  # then half a request: closed 1 s after its first byte, not kept alive for ever
        t, data = await answer(reader)
        assert 0.9 <= t < 10 and data.startswith(b"HTTP/1.1 408 "), (t, data)


async def test_an_oversized_head_is_431():
    async with Served(HttpLimits(max_header_bytes=4096)) as s:
        reader, writer = await connect(s.port)
        writer.write(HEAD + b"X-Big: " + b"a" * 10_000)  # one header, no end to it
        t, data = await answer(reader)
        assert data.startswith(b"HTTP/1.1 431 ") and b"larger than 4096 bytes" in data, data


async def test_a_body_that_stops_is_closed_and_a_slow_one_is_not():
    # pieces 0.4 s apart against a 2 s pause: margin for a loaded machine's event loop
    async with Served(HttpLimits(body_timeout_s=2.0, header_timeout_s=1.0)) as s:
        reader, writer = await connect(s.port)
        writer.write(b"POST /upload HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n" + b"x" * 10)
        t, data = await answer(reader)
        assert 1.9 <= t < 20 and data == b"", (t, data)  # closed: the body stopped for 2 s
        # a body that keeps coming, each piece within the pause, for longer than both timeouts together
        reader, writer = await connect(s.port)
        writer.write(b"POST /upload HTTP/1.1\r\nHost: x\r\nContent-Length: 10\r\nConnection: close\r\n\r\n")
        for _ in range(10):
            await asyncio.sleep(0.4)
            writer.write(b"x")
        _, data = await answer(reader)
        assert data.startswith(b"HTTP/1.1 200") and data.endswith(b'{"size": 10}'), data
        # a client that waits for 100 Continue the application has not asked for yet is not cut off
        reader, writer = await connect(s.port)
        writer.write(b"POST /slow-upload HTTP/1.1\r\nHost: x\r\nContent-Length: 3\r\nExpect: 100-continue\r\n"
                     b"Connection: close\r\n\r\n")
        assert await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 30) == b"HTTP/1.1 100 Continue\r\n\r\n"
        writer.write(b"abc")
        _, data = await answer(reader)
        assert data.startswith(b"HTTP/1.1 200") and data.endswith(b'{"size": 3}'), data
        # a large upload at full speed
        reader, writer = await connect(s.port)
        big = 8 << 20
        writer.write(b"POST /upload HTTP/1.1\r\nHost: x\r\nContent-Length: %d\r\nConnection: close\r\n\r\n" % big)
        writer.write(b"y" * big)
        _, data = await answer(reader, 60)
        assert data.endswith(b'{"size": %d}' % big), data[-200:]


async def test_a_streamed_answer_outlives_every_deadline():
    async with Served(HttpLimits(body_timeout_s=0.5, header_timeout_s=0.5)) as s:
        t0 = time.monotonic()
        data = await get(s.port, "/stream")
        assert data.count(b"tick") == 20 and time.monotonic() - t0 >= 2.0


async def test_per_peer_cap_refuses_and_the_total_cap_evicts_the_connection_idle_longest():
    try:
        probe = await connect(1, "127.0.0.2")
    except ConnectionRefusedError:
        pass  # 127.0.0.2 is a loopback source address here
    except OSError:
        pytest.skip("this machine has no 127.0.0.2 (the whole of 127/8 is loopback on Linux)")
    else:
        probe[1].close()
    async with Served(HttpLimits(max_per_peer=5, max_connections=8, header_timeout_s=60)) as s:
        mine = [await connect(s.port, "127.0.0.2") for _ in range(5)]
        for _, w in mine:
            w.write(HEAD)
        await asyncio.sleep(0.2)
        sixth = await connect(s.port, "127.0.0.2")
        t, data = await answer(sixth[0])
        assert data.startswith(b"HTTP/1.1 503 ") and b"too many connections from 127.0.0.2 (at most 5)" in data
        assert b"retry-after: 1" in data.lower()
        others = [await connect(s.port, "127.0.0.3") for _ in range(3)]  # the total (8) is reached
        for _, w in others:
            w.write(HEAD)
        await asyncio.sleep(0.2)
        assert s.book.open == 8
        # a newcomer from a third address: the connection idle longest (127.0.0.2's first) is closed for it
        assert b'"ok"' in await get(s.port)
        t, data = await answer(mine[0][0])
        assert data == b"" and s.book.evicted == 1
        assert s.book.open == 8 - 1 + 0  # the newcomer has been served and closed too
        for r, w in mine[1:] + others:
            w.close()


def test_the_connection_budget_leaves_the_robots_their_descriptors():
    assert connection_budget(2048, 8 * 275, open_files=20_000) == 2048
    assert connection_budget(2048, 8 * 275, open_files=4096) == 4096 - 256 - 2048  # robots capped at half
    assert connection_budget(2048, 8 * 275, open_files=1024) == 1024 - 256 - 512
    assert connection_budget(2048, 0, open_files=200) == 16


async def test_a_request_still_running_at_stop_is_one_log_line_not_a_traceback(caplog):
    """uvicorn cancels what outlives its graceful shutdown; StopCancels answers 503 and names the request
    instead of the traceback uvicorn would log ("Exception in ASGI application")."""
    from server.api.middleware import StopCancels

    async def forever(scope, receive, send):  # type: ignore[no-untyped-def]
        if scope["type"] == "http":
            await asyncio.sleep(3600)

    config = uvicorn.Config(StopCancels(forever), host="127.0.0.1", port=0, lifespan="off",
                            timeout_graceful_shutdown=0.2, log_config=None)
    server = uvicorn.Server(config)
    serving = asyncio.create_task(server.serve())
    while not server.started:
        await asyncio.sleep(0.01)
    port = server.servers[0].sockets[0].getsockname()[1]
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(b"GET /slow-report HTTP/1.1\r\nHost: x\r\n\r\n")
    await writer.drain()
    await asyncio.sleep(0.2)  # the request is in the application
    with caplog.at_level(logging.WARNING):
        server.should_exit = True
        await serving
    answer = await reader.read()
    assert answer.startswith(b"HTTP/1.1 503 ") and b"The server stopped before this request finished" in answer
    writer.close()
    assert "GET /slow-report was still running when the server stopped: cancelled" in caplog.text
    assert "Exception in ASGI application" not in caplog.text and "Traceback" not in caplog.text
