"""The robot wire protocol v1 (docs/design.md, "Robot protocol"): the one codec for agent, server and SDK.

Lines are ASCII, end in ``\\n`` (``\\r\\n`` accepted), fields are separated by
``,`` and points by ``;``; spaces around fields are ignored.  On the wire,
lengths are millimetres and angles degrees; every function here takes and
returns SI units (metres, radians) so callers never convert by hand.

Commands (client -> agent) parse into small dataclasses with
:func:`parse_command`; replies and events (agent -> client) are built with the
``format_*`` functions and parsed with :func:`parse_reply`.  Bad input raises
:class:`ProtocolError` carrying the ``ERR`` code to send back.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import Enum
from typing import Iterable, Sequence

import numpy as np

__all__ = [
    "MAX_LINE_BYTES",
    "MAX_POINTS",
    "PROTOCOL_VERSION",
    "BuildCommand",
    "Command",
    "ErrorCode",
    "Event",
    "PathCommand",
    "PlaceCommand",
    "ProtocolError",
    "QueryCommand",
    "Reply",
    "RobotState",
    "StopCommand",
    "decode_path",
    "encode_build",
    "encode_path",
    "encode_place",
    "format_error",
    "format_event",
    "format_hello",
    "format_ok",
    "format_status",
    "parse_command",
    "parse_reply",
]

PROTOCOL_VERSION = 1
MAX_LINE_BYTES = 1 << 20  # 1 MiB, terminator included
MAX_POINTS = 10_000
MAX_BLOCKS = 1000


class ErrorCode(str, Enum):
    """Codes of ``ERR,<code>,<message>`` replies."""

    SYNTAX = "SYNTAX"
    RANGE = "RANGE"
    STATE = "STATE"
    UNSUPPORTED = "UNSUPPORTED"
    TOOLONG = "TOOLONG"
    AUTH = "AUTH"


class RobotState(str, Enum):
    """States reported by ``ST`` replies."""

    IDLE = "IDLE"
    MOVING = "MOVING"
    DONE = "DONE"
    FAILED = "FAILED"


class Event(str, Enum):
    """Kinds of ``EV`` lines; ``FAIL`` carries a reason (COLLISION, TIMEOUT, STALLED, STOPPED)."""

    START = "START"
    WP = "WP"
    DONE = "DONE"
    FAIL = "FAIL"


FAIL_REASONS = ("COLLISION", "TIMEOUT", "STALLED", "STOPPED")


class ProtocolError(ValueError):
    """A refused line; ``code`` is the :class:`ErrorCode` to reply with."""

    def __init__(self, code: ErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = ErrorCode(code)
        self.message = message

    def line(self) -> str:
        """The ``ERR`` reply for this error (without terminator)."""
        return format_error(self.code, self.message)


# --------------------------------------------------------------------------- commands


@dataclass(frozen=True)
class PathCommand:
    """``T,T,P``: follow ``points`` ``(N, 3)``: x, y in metres, heading in radians."""

    points: np.ndarray


@dataclass(frozen=True)
class StopCommand:
    """``T,T,S``: stop now."""


@dataclass(frozen=True)
class QueryCommand:
    """``T,T,Q``: report the robot's state and believed pose."""


@dataclass(frozen=True)
class PlaceCommand:
    """``T,T,I``: the gripper places the robot at ``pose`` (x m, y m, heading rad)."""

    pose: tuple[float, float, float]


@dataclass(frozen=True)
class BuildCommand:
    """``T,T,B``: the gripper builds ``blocks`` ``(B, 5)``: cx, cy, w, h (m), angle (rad); empty clears."""

    blocks: np.ndarray


Command = PathCommand | StopCommand | QueryCommand | PlaceCommand | BuildCommand

_NUM = r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*"
_NUM_RE = re.compile(_NUM)


def _tuples_re(n: int) -> re.Pattern[str]:
    one = ",".join([_NUM] * n)
    return re.compile(rf"(?:{one})(?:;(?:{one}))*")


_POINTS_RE = _tuples_re(3)
_BLOCKS_RE = _tuples_re(5)


def _parse_tuples(payload: str, width: int, what: str, pattern: re.Pattern[str], limit: int) -> np.ndarray:
    """Parse ``a,b,c;d,e,f;...`` into a ``(N, width)`` float array of wire units."""
    if payload.count(";") + 1 > limit:
        raise ProtocolError(ErrorCode.RANGE, f"too many {what}s: {payload.count(';') + 1} > {limit}")
    if pattern.fullmatch(payload) is None:
        _explain_syntax(payload, width, what)
    values = np.array(payload.replace(";", ",").split(","), dtype=float).reshape(-1, width)
    if not np.isfinite(values).all():  # e.g. 1e999 overflows to inf
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise ProtocolError(ErrorCode.SYNTAX, f"{what} {bad + 1}: numbers must be finite")
    return values


def _explain_syntax(payload: str, width: int, what: str) -> None:
    """Find the first malformed tuple and raise a precise SYNTAX error (slow path, errors only)."""
    for i, item in enumerate(payload.split(";")):
        fields = item.split(",")
        if len(fields) != width:
            raise ProtocolError(
                ErrorCode.SYNTAX, f"{what} {i + 1}: expected {width} fields, got {len(fields)}"
            )
        for f in fields:
            if _NUM_RE.fullmatch(f) is None:
                shown = f.strip()[:20] or "(empty)"
                kind = "finite" if shown.lower().lstrip("+-") in ("nan", "inf", "infinity") else "a decimal"
                raise ProtocolError(ErrorCode.SYNTAX, f"{what} {i + 1}: {shown!r} is not {kind} number")
    raise ProtocolError(ErrorCode.SYNTAX, f"malformed {what} list")


def _wrap(a: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles (rad) to (-pi, pi]."""
    return -((-np.asarray(a) + np.pi) % (2 * np.pi) - np.pi)


def _check_range(xy_m: np.ndarray, field_size: tuple[float, float] | None, what: str) -> None:
    if field_size is None:
        return
    w, h = field_size
    out = (xy_m[:, 0] < 0) | (xy_m[:, 0] > w) | (xy_m[:, 1] < 0) | (xy_m[:, 1] > h)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        x, y = xy_m[i, :2] * 1000
        raise ProtocolError(
            ErrorCode.RANGE,
            f"{what} {i + 1} ({x:.0f}, {y:.0f}) mm is outside the field 0..{w * 1000:.0f} x 0..{h * 1000:.0f} mm",
        )


def parse_command(line: str | bytes, *, field_size: tuple[float, float] | None = None) -> Command:
    """Parse one client line (terminator optional) into a command, SI units.

    ``field_size`` (metres) enables the RANGE check of path points and
    placements.  Raises :class:`ProtocolError` for anything malformed.
    """
    if isinstance(line, bytes):
        if len(line) > MAX_LINE_BYTES:
            raise ProtocolError(ErrorCode.TOOLONG, f"line longer than {MAX_LINE_BYTES} bytes")
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError:
            raise ProtocolError(ErrorCode.SYNTAX, "line is not ASCII") from None
    elif len(line) > MAX_LINE_BYTES:
        raise ProtocolError(ErrorCode.TOOLONG, f"line longer than {MAX_LINE_BYTES} bytes")
    if not line.isascii():
        raise ProtocolError(ErrorCode.SYNTAX, "line is not ASCII")
    text = line.rstrip("\r\n").strip()
    if not text:
        raise ProtocolError(ErrorCode.SYNTAX, "empty line")
    head = text.split(",", 3)
    if len(head) < 3 or head[0].strip() != "T" or head[1].strip() != "T":
        raise ProtocolError(ErrorCode.SYNTAX, "commands start with T,T,<P|S|Q|I|B>")
    verb = head[2].strip()
    rest = head[3] if len(head) == 4 else None
    if verb == "P":
        if rest is None or not rest.strip():
            raise ProtocolError(ErrorCode.SYNTAX, "empty path: T,T,P needs at least one point x,y,a")
        pts = _parse_tuples(rest, 3, "point", _POINTS_RE, MAX_POINTS)
        out = np.column_stack([pts[:, :2] / 1000.0, _wrap(np.radians(pts[:, 2]))])
        _check_range(out, field_size, "point")
        return PathCommand(out)
    if verb in ("S", "Q"):
        if rest is not None and rest.strip():
            raise ProtocolError(ErrorCode.SYNTAX, f"T,T,{verb} takes no arguments")
        return StopCommand() if verb == "S" else QueryCommand()
    if verb == "I":
        if rest is None:
            raise ProtocolError(ErrorCode.SYNTAX, "T,T,I needs x,y,a")
        if ";" in rest:
            raise ProtocolError(ErrorCode.SYNTAX, "T,T,I takes exactly one pose x,y,a")
        pose = _parse_tuples(rest, 3, "pose", _POINTS_RE, 1)[0]
        xy = pose[None, :2] / 1000.0
        _check_range(xy, field_size, "pose")
        return PlaceCommand((float(xy[0, 0]), float(xy[0, 1]), float(_wrap(math.radians(pose[2])))))
    if verb == "B":
        if rest is None or not rest.strip():
            return BuildCommand(np.zeros((0, 5)))
        blocks = _parse_tuples(rest, 5, "block", _BLOCKS_RE, MAX_BLOCKS)
        if (blocks[:, 2:4] <= 0).any():
            i = int(np.flatnonzero((blocks[:, 2:4] <= 0).any(axis=1))[0])
            raise ProtocolError(ErrorCode.RANGE, f"block {i + 1}: width and height must be > 0")
        out = np.column_stack([blocks[:, :4] / 1000.0, np.radians(blocks[:, 4])])
        _check_range(out[:, :2], field_size, "block")
        return BuildCommand(out)
    raise ProtocolError(ErrorCode.UNSUPPORTED, f"unknown command T,T,{verb[:10]}")


# --------------------------------------------------------------------------- encoding


def _fmt(v: float, digits: int) -> str:
    s = f"{v:.{digits}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _finite_2d(a: Sequence | np.ndarray, width: int, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != width or len(arr) == 0:
        raise ValueError(f"`{name}` must have shape (N, {width}) with N >= 1, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"`{name}` must be finite (no NaN or inf)")
    return arr


def encode_path(path: Sequence | np.ndarray) -> str:
    """``T,T,P`` line (no terminator) for ``path`` ``(N, 3)`` in metres/radians, sent as mm/deg.

    Precision on the wire is 0.01 mm and 0.01 degrees.
    """
    p = _finite_2d(path, 3, "path")
    if len(p) > MAX_POINTS:
        raise ValueError(f"`path` has {len(p)} points; the protocol allows at most {MAX_POINTS}")
    mm = p[:, :2] * 1000.0
    deg = np.degrees(_wrap(p[:, 2]))
    return "T,T,P," + ";".join(
        f"{_fmt(x, 2)},{_fmt(y, 2)},{_fmt(a, 2)}" for (x, y), a in zip(mm.tolist(), deg.tolist())
    )


def decode_path(line: str | bytes) -> np.ndarray:
    """Inverse of :func:`encode_path`: the ``(N, 3)`` path in metres/radians of a ``T,T,P`` line."""
    cmd = parse_command(line)
    if not isinstance(cmd, PathCommand):
        raise ProtocolError(ErrorCode.SYNTAX, "not a T,T,P line")
    return cmd.points


def encode_place(pose: Sequence[float]) -> str:
    """``T,T,I`` line placing the robot at ``pose`` = (x m, y m, heading rad)."""
    p = _finite_2d([pose], 3, "pose")[0]
    return f"T,T,I,{_fmt(p[0] * 1000, 2)},{_fmt(p[1] * 1000, 2)},{_fmt(math.degrees(float(_wrap(p[2]))), 2)}"


def encode_build(blocks: Iterable[Sequence[float]]) -> str:
    """``T,T,B`` line for blocks given as (cx, cy, w, h, angle) in metres/radians; none clears."""
    rows = list(blocks)
    if not rows:
        return "T,T,B"
    b = _finite_2d(rows, 5, "blocks")
    return "T,T,B," + ";".join(
        ",".join([*(_fmt(v * 1000, 2) for v in r[:4]), _fmt(math.degrees(r[4]), 2)]) for r in b.tolist()
    )


# --------------------------------------------------------------------------- replies


def format_hello(robot_id: str, platform: str) -> str:
    """Greeting ``HELLO,<robot_id>,<platform>,1``."""
    for name, value in (("robot_id", robot_id), ("platform", platform)):
        if not value or any(c in value for c in ",;\r\n") or not value.isascii():
            raise ValueError(f"`{name}` must be non-empty ASCII without , ; or newlines")
    return f"HELLO,{robot_id},{platform},{PROTOCOL_VERSION}"


def format_ok(verb: str, count: int | None = None) -> str:
    """``OK,<verb>`` or ``OK,<verb>,<count>``."""
    return f"OK,{verb}" if count is None else f"OK,{verb},{count}"


def format_status(state: RobotState | str, pose: Sequence[float], t: float) -> str:
    """``ST,<state>,<x>,<y>,<a>,<t>`` from a pose in metres/radians and time in seconds."""
    x, y, a = pose
    return (
        f"ST,{RobotState(state).value},{_fmt(x * 1000, 1)},{_fmt(y * 1000, 1)},"
        f"{_fmt(math.degrees(float(_wrap(a))), 2)},{_fmt(t, 3)}"
    )


def format_event(kind: Event | str, t: float, *, index: int | None = None, reason: str | None = None) -> str:
    """``EV,START,t``, ``EV,WP,i,t``, ``EV,DONE,t`` or ``EV,FAIL,<reason>,t`` (t in seconds)."""
    k = Event(kind)
    ts = _fmt(t, 3)
    if k is Event.WP:
        if index is None:
            raise ValueError("`index` is required for WP events")
        return f"EV,WP,{index},{ts}"
    if k is Event.FAIL:
        if reason not in FAIL_REASONS:
            raise ValueError(f"`reason` must be one of {', '.join(FAIL_REASONS)}")
        return f"EV,FAIL,{reason},{ts}"
    return f"EV,{k.value},{ts}"


def format_error(code: ErrorCode | str, message: str) -> str:
    """``ERR,<code>,<message>``; the message is made single-line ASCII and capped at 200 chars."""
    clean = message.encode("ascii", "replace").decode().replace("\r", " ").replace("\n", " ")
    return f"ERR,{ErrorCode(code).value},{clean[:200]}"


@dataclass(frozen=True)
class Reply:
    """A parsed agent line: ``kind`` is HELLO, OK, ST, EV or ERR; ``fields`` the rest, stripped."""

    kind: str
    fields: tuple[str, ...]

    @property
    def time(self) -> float | None:
        """Experiment time (s) of ST and EV lines, else None."""
        if self.kind in ("ST", "EV") and self.fields:
            try:
                return float(self.fields[-1])
            except ValueError:
                return None
        return None


_REPLY_KINDS = {"HELLO", "OK", "ST", "EV", "ERR"}


def parse_reply(line: str | bytes) -> Reply:
    """Split an agent line into a :class:`Reply`; raises :class:`ProtocolError` if unrecognised."""
    if isinstance(line, bytes):
        line = line.decode("ascii", "replace")
    text = line.rstrip("\r\n").strip()
    kind, _, rest = text.partition(",")
    kind = kind.strip()
    if kind not in _REPLY_KINDS:
        raise ProtocolError(ErrorCode.SYNTAX, f"unrecognised agent line {text[:40]!r}")
    if kind == "ERR":  # the message may itself contain commas
        code, _, msg = rest.partition(",")
        return Reply(kind, (code.strip(), msg.strip()))
    return Reply(kind, tuple(f.strip() for f in rest.split(",")) if rest else ())
