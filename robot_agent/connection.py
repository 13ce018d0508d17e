"""One client connection of the wire protocol: line framing and a bounded outgoing queue.

After aiosmtpd's connection handler: this class only frames lines
(``readuntil(b"\\n")`` with a 1 MiB limit and recovery from an over-long line),
hands each line to its robot (:class:`robot_agent.robot.Robot`) and writes
what comes back.  Pure parsing lives in :mod:`robot_agent.protocol`.

Writing never blocks anybody else: lines go into this connection's bounded
queue and a writer task sends them with ``drain()``.  A client that sends
commands without reading the replies is throttled (its next line is read only
when its queue has room again); a client that reads nothing while its robot
emits events is disconnected once ``max_queue`` lines wait, so the
simulation never waits for a socket.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from .protocol import MAX_LINE_BYTES, ErrorCode, format_error

if TYPE_CHECKING:
    from .robot import Robot

__all__ = ["Connection", "TOOLONG"]

log = logging.getLogger("robot_agent.connection")

TOOLONG = object()  #: marker returned by :func:`read_line` for a discarded over-long line
_BIG_LINE = 64 * 1024  # lines longer than this are parsed in a worker thread


async def read_line(reader: asyncio.StreamReader) -> bytes | object:
    """The next line (terminator included), or :data:`TOOLONG` after discarding an over-long one.

    Raises ``asyncio.IncompleteReadError`` at end of stream (``partial`` holds
    an unterminated last line).  The reader's ``limit`` must be
    :data:`MAX_LINE_BYTES`.
    """
    try:
        return await reader.readuntil(b"\n")
    except asyncio.LimitOverrunError as exc:
        consumed = exc.consumed
    while True:  # discard up to and including the next newline
        await reader.readexactly(consumed)
        try:
            await reader.readuntil(b"\n")
            return TOOLONG
        except asyncio.LimitOverrunError as exc:
            consumed = exc.consumed


class Connection:
    """Serves one client of ``robot`` over ``reader``/``writer``."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, robot: "Robot",
                 *, max_queue: int = 50_000) -> None:
        self.reader, self.writer, self.robot = reader, writer, robot
        self.peer = writer.get_extra_info("peername")
        self.max_queue = max_queue
        self._queue: asyncio.Queue[str | None] = asyncio.Queue()
        self._room = asyncio.Event()
        self._room.set()
        self.closed = False

    def __repr__(self) -> str:
        return f"<Connection {self.peer} to {self.robot.robot_id}>"

    # ------------------------------------------------------------------ output

    def send(self, line: str) -> None:
        """Queue one line (without terminator); never blocks.  Overflow disconnects the client."""
        if self.closed:
            return
        if self._queue.qsize() >= self.max_queue:
            log.warning("%r: client does not read; %d lines pending, disconnecting", self, self._queue.qsize())
            self.close(abort=True)
            return
        self._queue.put_nowait(line)
        if self._queue.qsize() >= self.max_queue // 2:
            self._room.clear()

    def close(self, abort: bool = False) -> None:
        """Stop serving: the writer sends what is queued (unless ``abort``) and closes the socket."""
        if not self.closed:
            self.closed = True
            self._queue.put_nowait(None)
            self._room.set()
        if abort:
            self.writer.transport.abort()

    async def _write_loop(self) -> None:
        try:
            while True:
                line = await self._queue.get()
                chunks = []
                while line is not None:
                    chunks.append(line)
                    if self._queue.empty():
                        break
                    line = self._queue.get_nowait()
                if chunks:
                    self.writer.write(("\n".join(chunks) + "\n").encode("ascii", "replace"))
                    await self.writer.drain()
                if self._queue.qsize() < self.max_queue // 4:
                    self._room.set()
                if line is None:
                    return
        except (ConnectionError, OSError):
            self.closed = True
        finally:
            self.writer.close()

    # ------------------------------------------------------------------ input

    async def run(self) -> None:
        """Greet, then read and dispatch lines until the client leaves or is disconnected."""
        writer_task = asyncio.create_task(self._write_loop(), name=f"twb-writer-{self.peer}")
        self.send(self.robot.hello())
        try:
            while not self.closed:
                await self._room.wait()
                try:
                    line = await read_line(self.reader)
                except asyncio.IncompleteReadError as exc:
                    if exc.partial:
                        log.info("%r: disconnected after half a line (%d bytes ignored)", self, len(exc.partial))
                    break
                if self.closed:
                    break
                if line is TOOLONG:
                    self.send(format_error(ErrorCode.TOOLONG, f"line longer than {MAX_LINE_BYTES} bytes discarded"))
                    continue
                assert isinstance(line, bytes)
                for reply in await self.robot.handle(self, line, in_thread=len(line) > _BIG_LINE):
                    self.send(reply)
        except (ConnectionError, OSError) as exc:
            log.info("%r: connection lost: %s", self, exc)
        finally:
            self.robot.disconnected(self)
            self.close()
            try:
                await asyncio.wait_for(writer_task, 5.0)
            except asyncio.CancelledError:
                self.writer.transport.abort()
                raise
            except Exception:  # noqa: BLE001 - a client that never reads: the socket goes anyway
                self.writer.transport.abort()
