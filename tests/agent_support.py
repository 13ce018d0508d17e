"""Shared helpers of the agent tests: a real AgentHost on 127.0.0.1 and a line client.

Expected replies are built from the protocol's own constants and formatters so
the tests and the agent cannot drift apart.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from typing import AsyncIterator

import numpy as np

from robot_agent.host import AgentHost
from contract.protocol import format_hello, format_ok
from robot_agent.host.sinks import MemoryTrackerSink

READY_TIMEOUT_S = 5.0
REPLY_TIMEOUT_S = 10.0
OK_S = format_ok("S")
OK_I = format_ok("I")

# A sharp-cornered path (90 degree corners, points every 0.1 m as planners emit them), robot frame.
CORNERS = [(0.3, 0.3), (1.2, 0.3), (1.2, 0.8), (0.4, 0.8), (0.4, 1.3), (1.0, 1.3), (1.5, 1.5)]


def densify(corners: list[tuple[float, float]], step: float = 0.1, final_angle: float = math.pi / 2) -> np.ndarray:
    """Points every ``step`` m along the corners; headings along the segments, ``final_angle`` last."""
    out = [(*corners[0], 0.0)]
    for (ax, ay), (bx, by) in zip(corners[:-1], corners[1:]):
        n = max(1, math.ceil(math.hypot(bx - ax, by - ay) / step))
        a = math.atan2(by - ay, bx - ax)
        out += [(ax + (bx - ax) * j / n, ay + (by - ay) * j / n, a) for j in range(1, n + 1)]
    out[-1] = (*out[-1][:2], final_angle)
    return np.array(out)


class LineClient:
    """A protocol client over a real socket: ``send`` lines, ``recv`` lines with a timeout."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.stash: list[str] = []  # EV and PO lines that arrived while waiting for a reply

    @classmethod
    async def connect(cls, port: int, *, hello: str | None = None) -> "LineClient":
        reader, writer = await asyncio.wait_for(asyncio.open_connection("127.0.0.1", port), READY_TIMEOUT_S)
        client = cls(reader, writer)
        greeting = await client.recv()
        assert greeting.startswith("HELLO,"), greeting
        if hello is not None:
            assert greeting == hello
        return client

    async def send(self, line: str | bytes, end: bytes = b"\n") -> None:
        data = line.encode() if isinstance(line, str) else line
        self.writer.write(data + end)
        await self.writer.drain()

    async def recv(self, timeout: float = REPLY_TIMEOUT_S) -> str:
        line = await asyncio.wait_for(self.reader.readline(), timeout)
        if not line:
            raise ConnectionError("agent closed the connection")
        return line.decode("ascii").rstrip("\r\n")

    async def ask(self, line: str | bytes) -> str:
        """Send a line and return the reply; events and localisation lines arriving meanwhile go to :attr:`stash`."""
        await self.send(line)
        while True:
            reply = await self.recv()
            if not reply.startswith(("EV,", "PO,")):
                return reply
            self.stash.append(reply)

    async def until(self, *prefixes: str, timeout: float = REPLY_TIMEOUT_S) -> list[str]:
        """Lines (stashed events first) until one starts with any of ``prefixes`` (included)."""
        lines = []
        while True:
            line = self.stash.pop(0) if self.stash else await self.recv(timeout)
            lines.append(line)
            if line.startswith(prefixes):
                return lines

    async def close(self) -> None:
        self.writer.close()
        with contextlib.suppress(Exception):
            await self.writer.wait_closed()


@contextlib.asynccontextmanager
async def running_agents(**kwargs: object) -> AsyncIterator[AgentHost]:
    """An AgentHost on 127.0.0.1, port 0, as fast as possible by default; ready when yielded.

    Readiness: every robot's port answers with its greeting within
    ``READY_TIMEOUT_S`` (a clear failure instead of a hang otherwise).
    """
    kwargs.setdefault("time_scale", math.inf)
    kwargs.setdefault("tracker_sink", MemoryTrackerSink())
    host = AgentHost(host="127.0.0.1", port=0, **kwargs)  # type: ignore[arg-type]
    await asyncio.wait_for(host.start(), READY_TIMEOUT_S)
    try:
        for r in host.robots:
            try:
                c = await LineClient.connect(r.port, hello=format_hello(r.robot_id, host.params.platform))
            except (OSError, asyncio.TimeoutError) as exc:
                raise AssertionError(f"agent robot {r.robot_id} not ready on port {r.port}: {exc!r}") from exc
            await c.close()
        yield host
    finally:
        await asyncio.wait_for(host.stop(), READY_TIMEOUT_S)

