"""The robot port the program talks to: protocol v1 answers like a robot's, the first valid path kept.

:class:`RobotPort` holds no socket (the supervision loop frames the bytes
in and sends the replies out); every line it sends comes from
:mod:`contract.protocol`, the one codec of agent, server and SDK.
"""

from __future__ import annotations

import socket
from typing import Any, Callable, Optional

from contract.protocol import (MAX_LINE_BYTES, AuthCommand, Command, ErrorCode, LeaseCommand, LocalisationCommand,
                               PathCommand, ProtocolError, QueryCommand, RobotState, StopCommand, VelocityCommand, format_hello, format_ok,
                               format_status, parse_command)

__all__ = ["MAX_LINE_BYTES", "RobotPort", "send"]

#: received lines are logged up to this many characters
LOGGED_CHARS = 2000
#: a controller's conversation is logged up to this many lines (then counted)
LOGGED_LINES = 4000
#: what a controller program's robot port forwards to the run's robot (the closed-loop verbs)
RELAYED = (LocalisationCommand, VelocityCommand, StopCommand, QueryCommand)


class RobotPort:
    """One conversation: a greeting, an answer per line, done at the first valid ``T,T,P`` or when the program hangs up.

    ``field_size`` (m) bounds the path's points; ``start_pose`` (m, m, rad) is what ``T,T,Q`` reports.
    With ``relay`` (a controller program) the closed-loop verbs (:data:`RELAYED`) are not answered
    here but queued in ``forward`` for the run's robot, whose replies come back through
    :meth:`from_robot`; a path, placing and building are refused.
    """

    def __init__(self, *, robot_id: str, platform: str, field_size: tuple[float, float],
                 start_pose: tuple[float, float, float], relay: bool = False) -> None:
        self.relay = relay
        self.forward: list[str] = []  # relay: valid lines for the run's robot, in order
        self.unlogged = 0  # relay: lines past LOGGED_LINES
        self.robot_id, self.platform = robot_id, platform
        self.field_size, self.start_pose = field_size, start_pose
        self.connected = False
        self.path: Optional[list[list[float]]] = None
        self.path_at: Optional[float] = None  # s after the program's start
        self.log: list[list[str]] = []  # [direction, line]: "<" from the program, ">" to it
        self.refused: list[str] = []
        self._buf = b""
        self._discarding = False

    def greeting(self) -> bytes:
        """The ``HELLO`` line of a new connection."""
        self.connected = True
        return self._say(format_hello(self.robot_id, self.platform))

    def feed(self, data: bytes, now: float) -> tuple[bytes, bool]:
        """Bytes from the program (``b""``: it hung up) at ``now`` s; (the replies, whether the conversation is over)."""
        if not data:
            return b"", True
        out = b""
        self._buf += data
        while True:
            nl = self._buf.find(b"\n")
            if nl < 0:
                if len(self._buf) > MAX_LINE_BYTES:  # no end in sight: refuse once, drop until the next newline
                    if not self._discarding:
                        out += self._refuse(_too_long())
                    self._discarding = True
                    self._buf = b""
                return out, False
            line, self._buf = self._buf[:nl + 1], self._buf[nl + 1:]
            if self._discarding:
                self._discarding = False
                continue
            if len(line) > MAX_LINE_BYTES:
                out += self._refuse(_too_long())
                continue
            reply, done = self._line(line, now)
            out += reply
            if done:
                return out, True

    def _line(self, raw: bytes, now: float) -> tuple[bytes, bool]:
        text = raw.decode("ascii", "replace").rstrip("\r\n")
        shown = text[:LOGGED_CHARS] + (f"... ({len(text)} characters)" if len(text) > LOGGED_CHARS else "")
        self._note("<", shown)
        try:
            cmd = parse_command(raw, field_size=self.field_size)
        except ProtocolError as exc:
            return self._refuse(exc), False
        if self.relay:
            if isinstance(cmd, RELAYED):
                self.forward.append(text.strip())
                return b"", False
            if not isinstance(cmd, (AuthCommand, LeaseCommand)):
                message = "a controller program drives with T,T,V (and T,T,O, T,T,S, T,T,Q); the path is planned"
                return self._refuse(ProtocolError(ErrorCode.UNSUPPORTED, message)), False
        verbs: dict[type, Callable[[Any, float], tuple[bytes, bool]]] = {
            PathCommand: self._path, QueryCommand: self._query, StopCommand: self._stop,
            AuthCommand: self._open, LeaseCommand: self._open}
        return verbs.get(type(cmd), self._unsupported)(cmd, now)

    def _path(self, cmd: PathCommand, now: float) -> tuple[bytes, bool]:
        self.path = [[round(float(v), 6) + 0.0 for v in p] for p in cmd.points]
        self.path_at = now
        return self._say(format_ok("P", len(self.path))), True

    def _query(self, cmd: QueryCommand, now: float) -> tuple[bytes, bool]:
        return self._say(format_status(RobotState.IDLE, self.start_pose, 0.0)), False

    def _stop(self, cmd: StopCommand, now: float) -> tuple[bytes, bool]:
        return self._say(format_ok("S")), False

    def _open(self, cmd: Command, now: float) -> tuple[bytes, bool]:
        """``T,T,A`` / ``T,T,L``: this port has no key, like a standalone robot (any secret is fine)."""
        return self._say(format_ok("A" if isinstance(cmd, AuthCommand) else "L")), False

    def _unsupported(self, cmd: Command, now: float) -> tuple[bytes, bool]:
        message = "this robot port only takes a path (T,T,P), a query or a stop"
        return self._refuse(ProtocolError(ErrorCode.UNSUPPORTED, message)), False

    def _refuse(self, exc: ProtocolError) -> bytes:
        line = exc.line()
        self.refused.append(line)
        return self._say(line)

    def from_robot(self, line: str) -> bytes:
        """A line of the run's robot for the program (relay); ``PO`` lines are not logged."""
        if not line.startswith("PO,"):
            self._note(">", line)
        return line.encode("ascii", "replace") + b"\n"

    def _say(self, line: str) -> bytes:
        self._note(">", line)
        return line.encode() + b"\n"

    def _note(self, direction: str, line: str) -> None:
        if len(self.log) < LOGGED_LINES:
            self.log.append([direction, line])
        else:
            self.unlogged += 1


def _too_long() -> ProtocolError:
    return ProtocolError(ErrorCode.TOOLONG, f"line longer than {MAX_LINE_BYTES} bytes")


def send(conn: socket.socket, data: bytes, timeout_s: float = 1.0) -> None:
    """Send ``data`` to the program, waiting at most ``timeout_s`` (a program that does not read loses it)."""
    if not data:
        return
    try:
        conn.settimeout(timeout_s)
        conn.sendall(data)
    except OSError:
        pass
    finally:
        conn.setblocking(False)
