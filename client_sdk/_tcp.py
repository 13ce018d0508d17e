"""``send_path``: drive a robot agent directly over TCP with one ``T,T,P`` line (docs/design.md, "Robot protocol").

This is the testbed's raw way, open to planners in any language: connect, read
the ``HELLO`` greeting, authenticate with ``T,T,A,<secret>`` if the robot
needs it, send the path in millimetres and degrees, read the ``OK``/``ERR``
reply and, optionally, the events until ``EV,DONE`` or ``EV,FAIL``.  The wire
codec is :mod:`contract.protocol`, the one the agent itself uses.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass
from dataclasses import field as _field
from typing import Optional, Sequence

import numpy as np

from contract.protocol import ProtocolError, check_secret, encode_path, parse_reply

from ._exceptions import RobotError, TransportError

__all__ = ["PathReply", "path_with_headings", "send_path"]


@dataclass
class PathReply:
    """What a robot agent answered to a ``T,T,P`` line.

    ``reply`` is the ``OK,P,<n>`` or ``ERR,<code>,<message>`` line; with
    ``follow=True``, ``events`` holds every ``EV`` line up to the final one
    and ``outcome`` is ``"DONE"`` or ``"FAIL"`` (``reason`` e.g. ``COLLISION``).
    """

    robot_id: str
    platform: str
    line_sent: str
    reply: str
    ok: bool
    points: Optional[int] = None
    error_code: Optional[str] = None
    message: str = ""
    events: list[str] = _field(default_factory=list)
    outcome: Optional[str] = None
    reason: Optional[str] = None
    t_start: Optional[float] = None
    t_end: Optional[float] = None

    @property
    def execution_time_s(self) -> Optional[float]:
        """Experiment seconds from ``EV,START`` to the final event (None without ``follow``)."""
        if self.t_start is None or self.t_end is None:
            return None
        return self.t_end - self.t_start


def path_with_headings(path: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    """``(N, 3)`` x, y, theta from ``(N, 2)`` points (each faces the next; the last keeps its heading)."""
    p = np.asarray(path, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) < 1:
        raise ValueError(f"`path` must have shape (N, 2) or (N, 3) with N >= 1, got {p.shape}")
    if p.shape[1] == 3:
        return p
    d = np.diff(p, axis=0)
    theta = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    theta = np.append(theta, theta[-1] if len(theta) else 0.0)
    return np.column_stack([p, theta])


def send_path(host: str, port: int, path: Sequence[Sequence[float]] | np.ndarray | str, *,
              follow: bool = False, timeout: float = 10.0,
              follow_timeout: Optional[float] = 600.0, secret: Optional[str] = None) -> PathReply:
    """Send one path to the robot agent at ``host:port`` and return its reply.

    Parameters
    ----------
    host, port
        The robot agent (``twb agent --port P`` listens on 127.0.0.1:P).
    path : (N, 2) or (N, 3) array (m, m, rad), or str
        Points in the robot's frame; ``(N, 2)`` points get headings facing
        the next point.  A string is sent as is (a ready ``T,T,P,...`` line
        in millimetres and degrees, e.g. the output of ``twb plan --format ttp``).
    follow : bool
        Also read the events until ``EV,DONE`` or ``EV,FAIL`` (only after ``OK``).
    timeout : float, s
        Connecting and each reply.
    follow_timeout : float or None, s
        Wall seconds to wait for the final event (None: no limit).
    secret : str, optional
        Sent as ``T,T,A,<secret>`` before the path, for robots with a control
        key: the key, or the lease the testbed granted for a run.  If the
        robot refuses it the path is not sent and the reply is that
        ``ERR,AUTH,...`` line (``ok`` False, ``error_code`` ``"AUTH"``).

    Raises
    ------
    TransportError
        The agent cannot be reached, closed the connection or did not answer in time.
    RobotError
        The agent's lines are not protocol v1.
    ValueError
        ``path`` is not a finite ``(N, 2|3)`` array of at most 10 000 points, or
        ``secret`` is not 16-128 printable ASCII characters without ``,`` ``;``.
    """
    line = path.strip() if isinstance(path, str) else encode_path(path_with_headings(path))
    if secret is not None:
        check_secret(secret)
    where = f"{host}:{port}"
    try:
        with socket.create_connection((host, int(port)), timeout=timeout) as sock:
            reader = sock.makefile("rb")
            hello = _read(reader, where, "greeting")
            if hello.kind != "HELLO" or len(hello.fields) < 3:
                raise RobotError(f"{where} did not greet with HELLO,<robot_id>,<platform>,1")
            if secret is not None:
                sock.sendall(f"T,T,A,{secret}\n".encode("ascii"))
                reply_line, reply = _reply(reader, where)
            if secret is None or reply.kind == "OK":
                sock.sendall(line.encode("ascii") + b"\n")
                reply_line, reply = _reply(reader, where)
            out = PathReply(robot_id=hello.fields[0], platform=hello.fields[1], line_sent=line,
                            reply=reply_line, ok=reply.kind == "OK")
            if reply.kind == "OK" and len(reply.fields) >= 2:
                out.points = int(reply.fields[1])
            elif reply.kind == "ERR":
                out.error_code, out.message = reply.fields[0], reply.fields[1] if len(reply.fields) > 1 else ""
            else:
                raise RobotError(f"{where} answered {reply_line!r} to a T,T,P line")
            if follow and out.ok:
                sock.settimeout(follow_timeout)
                _follow(reader, where, out)
            return out
    except socket.timeout as exc:
        raise TransportError(f"the robot agent at {where} did not answer within {timeout:g} s") from exc
    except (ConnectionError, OSError) as exc:
        if isinstance(exc, (RobotError, TransportError)):
            raise
        raise TransportError(f"cannot reach the robot agent at {where}: {exc.strerror or exc}") from exc


def _follow(reader, where: str, out: PathReply) -> None:  # type: ignore[no-untyped-def]
    while True:
        text, ev = _read_line(reader, where, "event")
        if ev.kind != "EV" or not ev.fields:
            continue
        out.events.append(text)
        kind = ev.fields[0]
        if kind == "START":
            out.t_start = ev.time
        elif kind in ("DONE", "FAIL"):
            out.outcome, out.t_end = kind, ev.time
            if kind == "FAIL" and len(ev.fields) > 1:
                out.reason = ev.fields[1]
            return


def _reply(reader, where: str):  # type: ignore[no-untyped-def]
    """The next line that is not an event (none can come before this connection sent a path; be lenient)."""
    reply_line, reply = _read_line(reader, where, "reply")
    while reply.kind == "EV":
        reply_line, reply = _read_line(reader, where, "reply")
    return reply_line, reply


def _read_line(reader, where: str, what: str):  # type: ignore[no-untyped-def]
    raw = reader.readline()
    if not raw:
        raise TransportError(f"the robot agent at {where} closed the connection before its {what}")
    text = raw.decode("ascii", "replace").rstrip("\r\n")
    try:
        return text, parse_reply(text)
    except ProtocolError as exc:
        raise RobotError(f"{where} sent {text[:60]!r} as its {what}, which is not protocol v1") from exc


def _read(reader, where: str, what: str):  # type: ignore[no-untyped-def]
    return _read_line(reader, where, what)[1]
