"""The server's side of the robot wire protocol: one TCP connection to one robot agent.

Every line sent and received goes to ``on_line(direction, line, t, estimated)``
with the experiment time ``t`` on the agent's clock: taken from the line
itself for ``ST``/``EV`` lines (``estimated`` False), else extrapolated from
the last time the agent reported and the time scale (``estimated`` True).
Replies (``OK``/``ERR``/``ST``) answer requests in order; ``EV`` lines go to
an event queue.  A dead or silent agent raises
:class:`AgentUnavailable` — an infrastructure fault, not the job's.
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Callable, Optional

from contract.protocol import MAX_LINE_BYTES, ProtocolError, Reply, parse_reply

from .errors import AgentRefused, AgentUnavailable, AgentUnreachable

__all__ = ["AgentLink", "AgentRefused", "AgentUnavailable", "AgentUnreachable"]

LineLog = Callable[[str, str, Optional[float], bool], None]


class AgentLink:
    """A protocol-v1 client for one robot; use ``async with AgentLink.connect(...)``."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, *,
                 time_scale: float, on_line: LineLog) -> None:
        self._reader, self._writer = reader, writer
        self.time_scale = time_scale
        self.on_line = on_line
        self.hello: Optional[Reply] = None
        self._replies: asyncio.Queue[Reply | None] = asyncio.Queue()
        self.events: asyncio.Queue[Reply | None] = asyncio.Queue()
        self._anchor: Optional[tuple[float, float]] = None  # (wall, experiment time)
        self._reader_task: Optional[asyncio.Task] = None
        self._lock = asyncio.Lock()
        self.closed = False
        #: ``PO`` localisation lines (after ``T,T,O,1``) go here instead of the log: (the line, its fields)
        self.on_pose: Optional[Callable[[str, tuple[str, ...]], None]] = None

    @classmethod
    async def connect(cls, host: str, port: int, *, time_scale: float, on_line: LineLog,
                      control_key: Optional[str] = None, timeout_s: float = 5.0) -> "AgentLink":
        """Open the connection, read the ``HELLO`` greeting and, with a ``control_key``, authenticate."""
        try:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection(host, port, limit=MAX_LINE_BYTES), timeout_s)
        except (OSError, asyncio.TimeoutError, UnicodeError, ValueError) as exc:
            raise AgentUnreachable(f"cannot connect to robot agent {host}:{port}: {exc or 'timeout'}") from None
        link = cls(reader, writer, time_scale=time_scale, on_line=on_line)
        try:
            line = await asyncio.wait_for(reader.readline(), timeout_s)
        except (OSError, asyncio.TimeoutError):
            await link.close()
            raise AgentUnavailable(f"robot agent {host}:{port} sent no greeting") from None
        link._log("<", line)
        try:
            hello = parse_reply(line)
        except ProtocolError:
            hello = None
        if hello is None or hello.kind != "HELLO":
            await link.close()
            raise AgentUnavailable(f"{host}:{port} is not a robot agent (greeting {line[:40]!r})")
        link.hello = hello
        link._reader_task = asyncio.create_task(link._read_loop(), name=f"twb-agent-link-{port}")
        if control_key is not None:
            try:
                await link.request(f"T,T,A,{control_key}", timeout_s, shown="T,T,A,<control key>")
            except AgentRefused as exc:
                await link.close()
                raise AgentRefused(exc.code, f"the robot did not accept the testbed's control key ({exc.message})") \
                    from None
        return link

    async def __aenter__(self) -> "AgentLink":
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # ------------------------------------------------------------------ time

    def now(self) -> Optional[float]:
        """Estimated experiment time (s) on the agent's clock, or None before it first reported."""
        if self._anchor is None:
            return None
        wall, t = self._anchor
        if math.isinf(self.time_scale):
            return t
        return t + (time.monotonic() - wall) * self.time_scale

    def _log(self, direction: str, raw: bytes | str, t: Optional[float] = None) -> None:
        text = raw.decode("ascii", "replace") if isinstance(raw, bytes) else raw
        text = text.rstrip("\r\n")
        if t is not None:
            self.on_line(direction, text, t, False)
        else:
            est = self.now()
            self.on_line(direction, text, est, est is not None)

    # ------------------------------------------------------------------ I/O

    async def _read_loop(self) -> None:
        try:
            while True:
                raw = await self._reader.readline()
                if not raw:
                    break
                try:
                    reply = parse_reply(raw)
                except ProtocolError:
                    self._log("<", raw)
                    continue
                t = reply.time
                if t is not None:
                    self._anchor = (time.monotonic(), t)
                if reply.kind == "PO":  # many a second: not logged (the tracker stores the poses)
                    if self.on_pose is not None:
                        self.on_pose(raw.decode("ascii", "replace").strip(), reply.fields)
                    continue
                self._log("<", raw, t)
                if reply.kind == "EV":
                    self.events.put_nowait(reply)
                else:
                    self._replies.put_nowait(reply)
        except (OSError, asyncio.IncompleteReadError, ValueError):
            pass
        finally:
            self.closed = True
            self._replies.put_nowait(None)
            self.events.put_nowait(None)

    async def request(self, line: str, timeout_s: float, *, shown: Optional[str] = None) -> Reply:
        """Send one command and return its reply (``ERR`` raises :class:`AgentRefused`).

        ``shown``: what the protocol log records instead of ``line`` (secrets).
        """
        async with self._lock:
            if self.closed:
                raise AgentUnavailable("the connection to the robot agent is closed")
            self._log(">", shown if shown is not None else line)
            try:
                self._writer.write(line.encode("ascii") + b"\n")
                await asyncio.wait_for(self._writer.drain(), timeout_s)
                reply = await asyncio.wait_for(self._replies.get(), timeout_s)
            except asyncio.TimeoutError:
                raise AgentUnavailable(f"the robot agent did not answer {line[:12]}... within {timeout_s:.0f} s") from None
            except OSError as exc:
                raise AgentUnavailable(f"lost the robot agent: {exc}") from None
        if reply is None:
            raise AgentUnavailable("the robot agent closed the connection")
        if reply.kind == "ERR":
            raise AgentRefused(reply.fields[0] if reply.fields else "", reply.fields[1] if len(reply.fields) > 1 else "")
        return reply

    async def forward(self, line: str, timeout_s: float) -> str:
        """Send a program's command line and return the robot's reply line as sent (``ERR`` too, unraised)."""
        try:
            reply = await self.request(line, timeout_s)
        except AgentRefused as exc:
            return f"ERR,{exc.code},{exc.message}"
        return ",".join((reply.kind, *reply.fields))

    async def next_event(self, timeout_s: float) -> Optional[Reply]:
        """The next ``EV`` line; None on timeout; :class:`AgentUnavailable` if the agent is gone."""
        try:
            ev = await asyncio.wait_for(self.events.get(), timeout_s)
        except asyncio.TimeoutError:
            return None
        if ev is None:
            raise AgentUnavailable("the robot agent closed the connection during the run")
        return ev

    async def close(self) -> None:
        if self._reader_task is not None:
            self._reader_task.cancel()
        try:
            self._writer.close()
            await asyncio.wait_for(self._writer.wait_closed(), 2.0)
        except (OSError, asyncio.TimeoutError):
            pass
        self.closed = True
