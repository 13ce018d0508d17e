"""One client connection of the wire protocol: line framing, deadlines and a bounded outgoing queue.

After aiosmtpd's connection handler: this class only frames lines
(``readuntil(b"\\n")`` with a 1 MiB limit and recovery from an over-long line),
hands each line to its robot (:class:`robot_agent.host.robot.Robot`) and writes
what comes back.  Pure parsing lives in :mod:`contract.protocol`.

Writing never blocks anybody else: a line goes straight to the transport
while the client keeps up, else into this connection's bounded queue, which
a writer task sends with ``drain()``.  A client that sends
commands without reading the replies is throttled (its next line is read only
when its queue has room again); a client that reads nothing while its robot
emits events is disconnected once ``max_queue`` lines wait, so the
simulation never waits for a socket.

Deadlines (:class:`Limits`, wall seconds): a connection is closed with
``ERR,STATE,idle timeout`` when no line was accepted for ``idle_timeout_s``
(unless it drives the moving robot or has authenticated and its robot
moves), and with ``ERR,STATE,line timeout`` when a line is not complete
``line_timeout_s`` after its first byte.  A connection accepted *on
probation* (its robot had no room left) must authenticate with ``T,T,A`` as
its first line within ``probation_s``, else it gets ``ERR,STATE,too many
connections`` and is closed.
"""

from __future__ import annotations

import asyncio
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional, Protocol

from contract.protocol import MAX_LINE_BYTES, ErrorCode, RobotState, format_error

if TYPE_CHECKING:
    from contract.controller_specs import Selection

__all__ = ["MAX_AUTH_FAILURES", "TOOLONG", "TOO_MANY", "Connection", "Limits", "LineHandler"]

log = logging.getLogger("robot_agent.host.connection")

class LineHandler(Protocol):
    """What a connection hands its lines to: its robot (:class:`robot_agent.host.robot.Robot`)."""

    robot_id: str
    owner: Optional["Connection"]  #: the connection whose path is in progress

    def hello(self) -> str:
        """The greeting line."""

    def state(self) -> RobotState:
        """Where the robot stands."""

    def authorized(self, conn: "Connection") -> bool:
        """Whether ``conn`` holds a valid secret."""

    async def handle(self, conn: "Connection", line: bytes, *, in_thread: bool = False) -> list[str]:
        """The replies to one line ``conn`` sent."""

    def disconnected(self, conn: "Connection") -> None:
        """``conn`` closed."""


TOOLONG = object()  #: marker returned by :func:`read_line` for a discarded over-long line
TOO_MANY = "too many connections"
MAX_AUTH_FAILURES = 5  #: wrong secrets after which a connection is closed
_BIG_LINE = 64 * 1024  # lines longer than this are parsed in a worker thread
_DIRECT_BYTES = 64 * 1024  # bytes the transport may hold unsent for a line to skip the queue
_WAIT, _LINE, _SERVING = 0, 1, 2  # a connection's phases, for its deadlines


@dataclass(frozen=True)
class Limits:
    """Connection limits of each robot port; times in wall seconds.

    ``max_connections`` connections in all and ``max_per_peer`` from one IP
    address; beyond either, a robot with a control key still admits
    ``max_probation`` connections on probation (each must authenticate within
    ``probation_s``; the oldest is dropped for a newer one), a robot without
    one refuses.  ``idle_timeout_s``: longest wait for an accepted line;
    ``line_timeout_s``: longest time from a line's first byte to its end.
    """

    max_connections: int = 256
    max_per_peer: int = 32
    max_probation: int = 16
    idle_timeout_s: float = 300.0
    line_timeout_s: float = 30.0
    probation_s: float = 5.0

    def __post_init__(self) -> None:
        for name in ("max_connections", "max_per_peer", "max_probation"):
            if getattr(self, name) < 1:
                raise ValueError(f"`{name}` must be >= 1, got {getattr(self, name)}")
        for name in ("idle_timeout_s", "line_timeout_s", "probation_s"):
            if not getattr(self, name) > 0:  # also refuses NaN
                raise ValueError(f"`{name}` must be > 0 seconds, got {getattr(self, name)}")


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


class _Expired(Exception):
    """A deadline passed; ``reason`` goes into the final ``ERR,STATE`` line."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Connection:
    """Serves one client of ``robot`` over ``reader``/``writer``.

    Authentication state (kept by the robot's ``T,T,A`` / ``T,T,L`` verbs):
    ``auth`` is None, ``"key"`` (the control key), ``"lease"`` (the lease of
    grant number ``lease_grant``) or ``"open"`` (a robot without a control key);
    ``auth_failures`` counts wrong secrets.
    """

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, robot: LineHandler,
                 *, limits: Limits | None = None, probation: bool = False, max_queue: int = 50_000) -> None:
        self.reader, self.writer, self.robot = reader, writer, robot
        self.peer = writer.get_extra_info("peername")
        self.peer_host = str(self.peer[0]) if isinstance(self.peer, tuple) and self.peer else str(self.peer)
        self.limits = limits or Limits()
        self.probation = probation
        self.max_queue = max_queue
        self.auth: str | None = None
        self.lease_grant = 0
        self.auth_failures = 0
        self.controller: Selection | None = None  #: the controller of this connection's paths (``T,T,C``)
        self.localisation = False  #: whether this connection gets ``PO`` lines (``T,T,O``)
        self.clock: str | None = None  #: its clock while it drives the robot (``T,T,O,1,<clock>``; None: the host's)
        self._loop = asyncio.get_running_loop()
        self.opened = self._loop.time()
        self._last_accepted = self.opened
        self._phase = _WAIT  # what the connection waits for: a line (_WAIT), its end (_LINE), or it serves one
        self._line_start = self.opened  # loop time of the first byte of the line in progress
        self._timer: asyncio.TimerHandle | None = None  # the deadline timer (_check_deadline)
        self._queue: asyncio.Queue[str | None] = asyncio.Queue()
        self._room = asyncio.Event()
        self._room.set()
        self.closed = False

    def __repr__(self) -> str:
        return f"<Connection {self.peer} to {self.robot.robot_id}>"

    # ------------------------------------------------------------------ output

    def send(self, line: str) -> None:
        """Send one line (without terminator); never blocks.  Overflow disconnects the client.

        With nothing queued and the socket keeping up, the line goes to the transport at once (one
        ``send`` call, no hop through the writer task); otherwise it waits in the queue, in order."""
        if self.closed:
            return
        transport = self.writer.transport
        if self._queue.empty() and transport.get_write_buffer_size() < _DIRECT_BYTES and not transport.is_closing():
            transport.write((line + "\n").encode("ascii", "replace"))
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

    def refuse(self, reason: str) -> None:
        """Send ``ERR,STATE,<reason>`` as the last line and close."""
        self.send(format_error(ErrorCode.STATE, reason))
        self.close()

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

    # ------------------------------------------------------------------ deadlines

    def _idle_exempt(self) -> bool:
        """Whether this connection drives, or has authenticated for, its robot while it moves."""
        robot = self.robot
        if robot.state() is not RobotState.MOVING:
            return False
        return robot.owner is self or (self.auth is not None and robot.authorized(self))

    def _wait_deadline(self) -> float:
        """Loop time until which this connection may wait for its next line to start."""
        if self.probation:
            return self.opened + self.limits.probation_s
        return self._last_accepted + self.limits.idle_timeout_s

    def _check_deadline(self) -> None:
        """The deadline timer: end the connection if the deadline of what it waits for passed, else look again
        at that deadline, or one line timeout from now, whichever is first.

        Lines themselves never touch the timer (they only note the time): it runs at least once per line
        timeout, so a line that starts at ``t`` is looked at again by ``t + line_timeout_s`` at the latest,
        and from then on exactly at its deadline."""
        self._timer = None
        now = self._loop.time()
        deadline = math.inf
        if self._phase == _LINE:
            deadline = self._line_start + self.limits.line_timeout_s
            if self.probation:
                deadline = min(deadline, self._wait_deadline())
            if now >= deadline:
                return self._expire(TOO_MANY if self.probation else "line timeout")
        elif self._phase == _WAIT:
            deadline = self._wait_deadline()
            if now >= deadline:
                if self.probation:
                    return self._expire(TOO_MANY)
                if not self._idle_exempt():
                    return self._expire("idle timeout")
                self._last_accepted = now  # it drives the moving robot: it waits on
                deadline = self._wait_deadline()
        self._timer = self._loop.call_at(min(deadline, now + self.limits.line_timeout_s), self._check_deadline)

    def _expire(self, reason: str) -> None:
        """A deadline passed: the read in progress (or the next one) raises ``_Expired(reason)``."""
        self.reader.set_exception(_Expired(reason))
        self._room.set()  # a connection waiting for room reads next, and learns it

    async def _next_line(self) -> bytes | object:
        """The next line or :data:`TOOLONG`; ``_Expired`` when a deadline passes, and
        ``IncompleteReadError`` at the end of the stream."""
        self._phase = _WAIT
        first = await self.reader.readexactly(1)
        if first == b"\n":
            return first
        self._phase, self._line_start = _LINE, self._loop.time()
        rest = await read_line(self.reader)
        return rest if rest is TOOLONG else first + rest  # type: ignore[operator]

    # ------------------------------------------------------------------ input

    async def run(self) -> None:
        """Greet, then read and dispatch lines until the client leaves, is disconnected or times out."""
        writer_task = asyncio.create_task(self._write_loop(), name=f"twb-writer-{self.peer}")
        self.send(self.robot.hello())
        self._check_deadline()
        try:
            while not self.closed:
                if not self._room.is_set():
                    self._phase = _WAIT
                    await self._room.wait()
                try:
                    line = await self._next_line()
                except asyncio.IncompleteReadError as exc:
                    if exc.partial:
                        log.info("%r: disconnected after half a line (%d bytes ignored)", self, len(exc.partial))
                    break
                self._phase = _SERVING
                if self.closed:
                    break
                await self._serve(line)
        except _Expired as exc:
            log.info("%r: %s; closing", self, exc.reason)
            self.refuse(exc.reason)
        except (ConnectionError, OSError) as exc:
            log.info("%r: connection lost: %s", self, exc)
        finally:
            if self._timer is not None:
                self._timer.cancel()
            self.robot.disconnected(self)
            self.close()
            try:
                await asyncio.wait_for(writer_task, 5.0)
            except asyncio.CancelledError:
                self.writer.transport.abort()
                raise
            except Exception:  # noqa: BLE001 - a client that never reads: the socket goes anyway
                self.writer.transport.abort()

    async def _serve(self, line: bytes | object) -> None:
        """Reply to one line; apply the probation and wrong-secret rules."""
        if line is TOOLONG:
            replies = [format_error(ErrorCode.TOOLONG, f"line longer than {MAX_LINE_BYTES} bytes discarded")]
        else:
            assert isinstance(line, bytes)
            replies = await self.robot.handle(self, line, in_thread=len(line) > _BIG_LINE)
        if self.probation:  # the first line did not authenticate
            self.refuse(TOO_MANY)
            return
        for reply in replies:
            self.send(reply)
        if self.auth_failures >= MAX_AUTH_FAILURES:
            log.warning("%r: %d wrong secrets; closing", self, self.auth_failures)
            self.close()
        elif replies and not replies[0].startswith("ERR,"):
            self._last_accepted = self._loop.time()
