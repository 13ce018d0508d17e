"""The robot wire protocol v1 (docs/design.md, "Robot protocol"): the one codec for agent, server and SDK.

Lines are ASCII, end in ``\\n`` (``\\r\\n`` accepted), fields are separated by
``,`` and points by ``;``; spaces around fields are ignored.  On the wire,
lengths are millimetres and angles degrees; every function here takes and
returns SI units (metres, radians) so callers never convert by hand.

Commands (client -> agent) parse into small dataclasses with
:func:`parse_command` (or in two steps: :func:`split_command` checks the
framing and splits off the verb, :func:`parse_arguments` parses the rest);
replies and events (agent -> client) are built with the ``format_*``
functions and parsed with :func:`parse_reply`.  Bad input raises
:class:`ProtocolError` carrying the ``ERR`` code to send back.

Lines come from anybody who can reach a robot port, so parsing takes linear
time whatever the input and uses no regular expressions: split first, then
check each field with a bounded rule (see ``docs/protocol.md``, "Numbers").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Iterable, Sequence

import numpy as np

__all__ = [
    "CLOCKS",
    "MAX_COMPUTE_MS",
    "MAX_BLOCKS",
    "MAX_LINE_BYTES",
    "MAX_NUMBER_CHARS",
    "MAX_POINTS",
    "MAX_SECRET_CHARS",
    "MIN_SECRET_CHARS",
    "PROTOCOL_VERSION",
    "AuthCommand",
    "BuildCommand",
    "Command",
    "ControllerCommand",
    "LocalisationCommand",
    "VelocityCommand",
    "ErrorCode",
    "Event",
    "LeaseCommand",
    "MAX_MOVING",
    "MovingCommand",
    "PathCommand",
    "PlaceCommand",
    "ProtocolError",
    "QueryCommand",
    "Reply",
    "RobotState",
    "StopCommand",
    "check_secret",
    "decode_path",
    "encode_build",
    "encode_moving",
    "encode_controller",
    "encode_path",
    "encode_place",
    "format_error",
    "format_event",
    "format_hello",
    "format_localisation",
    "format_localisations",
    "format_ok",
    "format_status",
    "parse_arguments",
    "parse_command",
    "parse_reply",
    "split_command",
]

PROTOCOL_VERSION = 1
MAX_LINE_BYTES = 1 << 20  # 1 MiB, terminator included
MAX_POINTS = 10_000
MAX_BLOCKS = 1000
MAX_NUMBER_CHARS = 32  # a number's characters, surrounding spaces not counted
MIN_SECRET_CHARS, MAX_SECRET_CHARS = 16, 128
#: how a robot's clock treats a closed-loop connection (``T,T,O,1,<clock>``): wait for its answer to every
#: ``PO`` line, or run on (docs/protocol.md, "Closed-loop programs")
CLOCKS = ("lockstep", "free")
MAX_COMPUTE_MS = 60_000.0  #: the largest compute time a ``T,T,V`` may state (ms)
MAX_MOVING = 16  #: moving obstacles of one robot (the tracker's robot budget; planners.moving)
MAX_TRACK_POINTS = 1000  #: waypoints of one moving obstacle
MAX_NAME_CHARS = 64  #: a controller's or parameter's name in ``T,T,C``
MAX_CONTROLLER_PARAMS = 16
_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyz0123456789_")
#: how far a block may reach beyond its robot's area (wire rounding); the same rule as environment files
#: (planners.environment: not imported here, the codec stays light for the sandbox and the SDK)
BLOCK_TOLERANCE_M = 0.001


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
    """Kinds of ``EV`` lines; ``FAIL`` carries a reason (COLLISION, TIMEOUT, STALLED, STOPPED); ``REPLAN`` the
    new path's number of points and the planning time (a replanning controller, docs/controllers.md)."""

    START = "START"
    WP = "WP"
    REPLAN = "REPLAN"
    DONE = "DONE"
    FAIL = "FAIL"


FAIL_REASONS = ("COLLISION", "TIMEOUT", "STALLED", "STOPPED", "WATCHDOG")


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


@dataclass(frozen=True)
class AuthCommand:
    """``T,T,A``: authenticate this connection with ``secret`` (the control key or the current lease)."""

    secret: str


@dataclass(frozen=True)
class LeaseCommand:
    """``T,T,L``: grant ``lease`` as a second secret of this robot; None revokes the current lease."""

    lease: str | None


@dataclass(frozen=True)
class MovingCommand:
    """``T,T,M``: the robot's moving obstacles, each ``(params, waypoints)``: params ``(4,)`` radius m,
    speed m/s, repeat code (0 once, 1 loop, 2 pingpong), delay s; waypoints ``(K, 2)`` m; none clears."""

    obstacles: tuple[tuple[np.ndarray, np.ndarray], ...]


@dataclass(frozen=True)
class ControllerCommand:
    """``T,T,C``: the controller of the paths this connection sends from now on: ``name`` (None: the
    default, the motor schema) with ``params`` (each in its own unit, SI, as its name says)."""

    name: str | None
    params: dict[str, float]


@dataclass(frozen=True)
class LocalisationCommand:
    """``T,T,O,1[,<clock>]`` / ``T,T,O,0``: send (or stop sending) this connection ``PO`` localisation lines.

    ``clock`` (:data:`CLOCKS`) is how the robot's clock treats this connection while it drives the robot in
    velocity mode: ``lockstep`` waits for its answer (a ``T,T,V``) to every ``PO`` line, ``free`` runs on;
    None: the robot's default (docs/protocol.md)."""

    on: bool
    clock: str | None = None


@dataclass(frozen=True)
class VelocityCommand:
    """``T,T,V,<v>,<w>[,<c>]``: drive with body velocities ``v`` (m/s) and ``w`` (rad/s) until the next one;
    ``compute_s`` (the optional ``c``, ms on the wire): the controller's compute time for this answer, which
    a robot in lockstep applies as latency (docs/protocol.md); None: not stated."""

    v: float
    w: float
    compute_s: float | None = None


Command = (PathCommand | StopCommand | QueryCommand | PlaceCommand | BuildCommand | AuthCommand | LeaseCommand
           | MovingCommand | ControllerCommand | LocalisationCommand | VelocityCommand)

# --------------------------------------------------------------------------- parsing
#
# Untrusted input: no regular expressions.  Every step is a split, a count or a
# byte-class check in linear time; a number is at most MAX_NUMBER_CHARS long
# before float() sees it.  Once _line_bytes has refused control characters and
# non-ASCII bytes, the space is the only whitespace left, so the fast
# str.strip() strips exactly the spaces around fields.

_CONTROL = bytes(range(0x20)) + b"\x7f"
_CONTROL_NAMES = (
    "NUL SOH STX ETX EOT ENQ ACK BEL BS TAB LF VT FF CR SO SI "
    "DLE DC1 DC2 DC3 DC4 NAK SYN ETB CAN EM SUB ESC FS GS RS US"
).split()
_LIST_BYTES = b"0123456789+-.eE ,;"  # everything a list of numbers may contain
_IS_CONTROL = np.zeros(256, dtype=bool)
_IS_CONTROL[list(_CONTROL)] = True
_NOT_LIST = np.ones(256, dtype=bool)
_NOT_LIST[list(_LIST_BYTES)] = False
_SIGNS = ("+", "-")
_CONVERT_CHUNK = 4096  # fields per numpy conversion (a few ms at most)
_SHORT_ITEM = 256  # characters up to which a single item is parsed field by field (_parse_item)


def _line_bytes(line: str | bytes) -> bytes:
    """``line`` as ASCII bytes without its terminator (``\\n``, optionally after one ``\\r``)."""
    if len(line) > MAX_LINE_BYTES:
        raise ProtocolError(ErrorCode.TOOLONG, f"line longer than {MAX_LINE_BYTES} bytes")
    if isinstance(line, str):
        if not line.isascii():
            raise ProtocolError(ErrorCode.SYNTAX, "line is not ASCII")
        raw = line.encode("ascii")
    else:
        raw = bytes(line)
        if not raw.isascii():
            raise ProtocolError(ErrorCode.SYNTAX, "line is not ASCII")
    if raw.endswith(b"\n"):
        raw = raw[:-1]
    if raw.endswith(b"\r"):
        raw = raw[:-1]
    _check_controls(raw)
    return raw


def _check_controls(raw: bytes) -> None:
    """Refuse any control character (0x00-0x1F, 0x7F), naming it and its 1-based column."""
    if len(raw.translate(None, _CONTROL)) == len(raw):
        return
    col = int(np.flatnonzero(_IS_CONTROL[np.frombuffer(raw, dtype=np.uint8)])[0])
    code = raw[col]
    name = "DEL" if code == 0x7F else _CONTROL_NAMES[code]
    raise ProtocolError(
        ErrorCode.SYNTAX,
        f"control character 0x{code:02X} ({name}) at column {col + 1}; only spaces may surround fields",
    )


def split_command(line: str | bytes) -> tuple[str, str | None]:
    """Check the framing of one client line and split off its verb: ``(verb, arguments)``.

    ``arguments`` is everything after ``T,T,<verb>,`` (None without that
    comma).  Raises :class:`ProtocolError` for a line over
    :data:`MAX_LINE_BYTES`, non-ASCII bytes, control characters, an empty line
    or one that does not start with ``T,T,``.  Linear time.
    """
    text = _line_bytes(line).decode("ascii")
    if not text.strip():
        raise ProtocolError(ErrorCode.SYNTAX, "empty line")
    head = text.split(",", 3)
    if len(head) < 3 or head[0].strip() != "T" or head[1].strip() != "T":
        raise ProtocolError(ErrorCode.SYNTAX, "commands start with T,T,<P|S|Q|I|B|M|C|O|V|A|L>")
    return head[2].strip(), (head[3] if len(head) == 4 else None)


def _is_decimal(s: str) -> bool:
    """Whether ``s`` (no surrounding spaces) is ``[+-]digits[.digits][e[+-]digits]`` (digits on one side
    of the dot may be missing, not on both)."""
    if not s.isascii():
        return False
    mantissa, e, exponent = s.replace("E", "e").partition("e")
    if e:
        if exponent[:1] in _SIGNS:
            exponent = exponent[1:]
        if not exponent.isdigit():  # also refuses a second e
            return False
    if mantissa[:1] in _SIGNS:
        mantissa = mantissa[1:]
    whole, _, frac = mantissa.partition(".")
    return bool(whole or frac) and (not whole or whole.isdigit()) and (not frac or frac.isdigit())


def _number_error(field: str) -> str | None:
    """Why ``field`` is not a protocol number, or None."""
    s = field.strip()
    if len(s) > MAX_NUMBER_CHARS:
        return f"number {s[:20]!r}... has {len(s)} characters (at most {MAX_NUMBER_CHARS})"
    if _is_decimal(s):
        return None
    shown = s or "(empty)"  # at most MAX_NUMBER_CHARS
    kind = "a finite" if shown.lower().lstrip("+-") in ("nan", "inf", "infinity") else "a decimal"
    return f"{shown!r} is not {kind} number"


def _item_error(item: str, width: int) -> str | None:
    """Why ``item`` (one point or block) is not ``width`` protocol numbers, or None."""
    fields = item.split(",")
    if len(fields) != width:
        return f"expected {width} fields, got {len(fields)}"
    for f in fields:
        why = _number_error(f)
        if why:
            return why
    return None


@dataclass(frozen=True)
class _Layout:
    """Where the fields of a list are: per field its item and length, where each item ends,
    and the first item that is surely malformed (wrong field count, a character no number has)."""

    item: np.ndarray
    length: np.ndarray
    ends: np.ndarray
    first_bad: int


def _layout(raw: bytes, width: int, count: int) -> _Layout:
    """One vectorised pass over the separators and character classes of a ``count``-item list."""
    a = np.frombuffer(raw, dtype=np.uint8)
    seps = np.flatnonzero((a == 44) | (a == 59))  # "," and ";"
    semi = a[seps] == 59
    item = np.zeros(len(seps) + 1, dtype=np.int64)
    np.cumsum(semi, out=item[1:])
    length = np.diff(np.concatenate(([-1], seps, [len(raw)]))) - 1
    wrong = np.flatnonzero(np.bincount(item, minlength=count) != width)
    first_bad = int(wrong[0]) if len(wrong) else count
    if raw.translate(None, _LIST_BYTES):  # a character no number has
        pos = int(np.flatnonzero(_NOT_LIST[a])[0])
        first_bad = min(first_bad, int(item[np.searchsorted(seps, pos)]))
    return _Layout(item, length, np.append(seps[semi], len(raw)), first_bad)


class _Unparsable(Exception):
    """Field ``index`` of a list is not a number."""

    def __init__(self, index: int) -> None:
        super().__init__(index)
        self.index = index


def _to_floats(fields: list[str]) -> np.ndarray:
    """``fields`` as floats, converted by numpy in chunks so that a worker thread parsing a long
    line lets the event loop run in between; :class:`_Unparsable` names the first bad field."""
    chunks = []
    for start in range(0, len(fields), _CONVERT_CHUNK):
        chunk = fields[start : start + _CONVERT_CHUNK]
        try:
            chunks.append(np.array(chunk, dtype=float))
        except ValueError:
            raise _Unparsable(start + _first_unparsable(chunk)) from None
    return np.concatenate(chunks) if chunks else np.zeros(0)


def _first_unparsable(fields: list[str]) -> int:
    """Index of the first field ``float()`` refuses (numpy refused the list)."""
    for j, f in enumerate(fields):
        try:
            float(f)
        except ValueError:
            return j
    raise ProtocolError(ErrorCode.SYNTAX, "malformed number list")  # numpy refused what float() accepts


def _parse_item(item: str, width: int, what: str) -> np.ndarray:
    """One short item ``a,b,...`` (``T,T,V``, ``T,T,I``) as ``width`` floats, field by field: the same
    numbers and the same refusals as the vectorised pass over a list, without its fixed cost."""
    fields = [f.strip() for f in item.split(",")]
    if len(fields) != width or not all(len(f) <= MAX_NUMBER_CHARS and _is_decimal(f) for f in fields):
        raise ProtocolError(ErrorCode.SYNTAX, f"{what} 1: {_item_error(item, width)}")
    values = [float(f) for f in fields]
    if not all(map(math.isfinite, values)):  # e.g. 1e999 overflows to inf
        raise ProtocolError(ErrorCode.SYNTAX, f"{what} 1: numbers must be finite")
    return np.array(values)


def _parse_tuples(payload: str, width: int, what: str, limit: int) -> np.ndarray:
    """Parse ``a,b,c;d,e,f;...`` into a ``(N, width)`` float array of wire units, in linear time.

    The fast path finds the fields, their lengths and any character no number
    has in one vectorised pass, and numpy converts the fields.  Only a
    malformed list is looked at item by item, to explain its first bad item.
    """
    count = payload.count(";") + 1
    if count > limit:
        raise ProtocolError(ErrorCode.RANGE, f"too many {what}s: {count} > {limit}")
    if count == 1 and len(payload) <= _SHORT_ITEM:
        return _parse_item(payload, width, what)[None, :]
    layout = _layout(payload.encode("ascii"), width, count)
    stop = layout.first_bad  # items from here on are not converted
    long_items = np.unique(layout.item[layout.length > MAX_NUMBER_CHARS])
    long_items = long_items[long_items < stop]
    items = payload.split(";") if len(long_items) else None
    for i in long_items.tolist():  # a long field is fine only when spaces pad a short number
        if _item_error(items[i], width):  # type: ignore[index]
            stop = i
            break
    head = payload[: layout.ends[stop - 1]] if stop else ""  # the items before `stop`
    fields = head.replace(";", ",").split(",") if head else []
    try:
        values = _to_floats(fields)
    except _Unparsable as exc:
        stop = exc.index // width
    if stop < count:
        why = _item_error((items or payload.split(";"))[stop], width)
        raise ProtocolError(ErrorCode.SYNTAX, f"{what} {stop + 1}: {why or 'malformed'}")
    values = values.reshape(-1, width)
    if not np.isfinite(values).all():  # e.g. 1e999 overflows to inf
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise ProtocolError(ErrorCode.SYNTAX, f"{what} {bad + 1}: numbers must be finite")
    return values


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


def _check_blocks_inside(blocks_m: np.ndarray, field_size: tuple[float, float] | None) -> None:
    """Refuse blocks whose rotated rectangle reaches beyond the area ``[0,w] x [0,h]`` (m)."""
    if field_size is None or not len(blocks_m):
        return
    w, h = field_size
    cx, cy, bw, bh, a = blocks_m.T
    c, s = np.abs(np.cos(a)), np.abs(np.sin(a))
    ex, ey = (bw * c + bh * s) / 2, (bw * s + bh * c) / 2  # half extents of the rotated rectangle
    tol = BLOCK_TOLERANCE_M
    out = (cx - ex < -tol) | (cx + ex > w + tol) | (cy - ey < -tol) | (cy + ey > h + tol)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise ProtocolError(
            ErrorCode.RANGE,
            f"block {i + 1} ({bw[i] * 1000:.0f} x {bh[i] * 1000:.0f} mm at "
            f"({cx[i] * 1000:.0f}, {cy[i] * 1000:.0f}) mm, {math.degrees(a[i]):.0f} deg) reaches beyond the area "
            f"0..{w * 1000:.0f} x 0..{h * 1000:.0f} mm",
        )


def check_secret(secret: str) -> str:
    """Return ``secret`` if it may serve as a control key or lease, else raise ``ValueError``.

    A secret is 16 to 128 printable ASCII characters (0x20-0x7E) without ``,``
    or ``;`` and without a space at either end.
    """
    if not MIN_SECRET_CHARS <= len(secret) <= MAX_SECRET_CHARS:
        raise ValueError(f"a secret has {MIN_SECRET_CHARS} to {MAX_SECRET_CHARS} characters, got {len(secret)}")
    if not (secret.isascii() and secret.isprintable()) or "," in secret or ";" in secret:
        raise ValueError("a secret is printable ASCII without , or ;")
    if secret != secret.strip(" "):
        raise ValueError("a secret neither starts nor ends with a space")
    return secret


def _secret(rest: str | None, verb: str) -> str:
    text = "" if rest is None else rest.strip()
    if not text:
        raise ProtocolError(ErrorCode.SYNTAX, f"T,T,{verb} needs a secret: T,T,{verb},<secret>")
    try:
        return check_secret(text)
    except ValueError as exc:
        raise ProtocolError(ErrorCode.SYNTAX, str(exc)) from None


def parse_arguments(verb: str, rest: str | None, *, field_size: tuple[float, float] | None = None) -> Command:
    """The command for ``verb`` and its ``rest`` (as :func:`split_command` returns them), SI units.

    ``field_size`` (metres) enables the RANGE checks of path points,
    placements and blocks.  Raises :class:`ProtocolError` for anything
    malformed.  Linear time in ``len(rest)``.
    """
    if verb == "P":
        if rest is None or not rest.strip():
            raise ProtocolError(ErrorCode.SYNTAX, "empty path: T,T,P needs at least one point x,y,a")
        pts = _parse_tuples(rest, 3, "point", MAX_POINTS)
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
        pose = _parse_tuples(rest, 3, "pose", 1)[0]
        xy = pose[None, :2] / 1000.0
        _check_range(xy, field_size, "pose")
        return PlaceCommand((float(xy[0, 0]), float(xy[0, 1]), float(_wrap(math.radians(pose[2])))))
    if verb == "B":
        if rest is None or not rest.strip():
            return BuildCommand(np.zeros((0, 5)))
        blocks = _parse_tuples(rest, 5, "block", MAX_BLOCKS)
        if (blocks[:, 2:4] <= 0).any():
            i = int(np.flatnonzero((blocks[:, 2:4] <= 0).any(axis=1))[0])
            raise ProtocolError(ErrorCode.RANGE, f"block {i + 1}: width and height must be > 0")
        out = np.column_stack([blocks[:, :4] / 1000.0, np.radians(blocks[:, 4])])
        _check_range(out[:, :2], field_size, "block")
        _check_blocks_inside(out, field_size)
        return BuildCommand(out)
    if verb == "M":
        return _moving(rest, field_size)
    if verb == "C":
        return _controller(rest)
    if verb == "O":
        flag, _, clock = ("" if rest is None else rest).partition(",")
        flag, clock = flag.strip(), clock.strip() if _ else None
        if flag not in ("0", "1") or (clock is not None and (flag == "0" or clock not in CLOCKS)):
            raise ProtocolError(ErrorCode.SYNTAX, "T,T,O takes 1 (send PO lines), optionally with the clock "
                                                  "(T,T,O,1,lockstep or T,T,O,1,free), or 0 (stop)")
        return LocalisationCommand(flag == "1", clock)
    if verb == "V":
        if rest is None or ";" in rest or rest.count(",") not in (1, 2):
            raise ProtocolError(ErrorCode.SYNTAX, "T,T,V takes v,w (mm/s, deg/s), optionally with the compute "
                                                  "time c (ms): v,w,c")
        row = _parse_tuples(rest, rest.count(",") + 1, "velocity", 1)[0]
        compute = None
        if len(row) == 3:
            if not 0.0 <= row[2] <= MAX_COMPUTE_MS:
                raise ProtocolError(ErrorCode.RANGE, f"compute time must be 0 to {MAX_COMPUTE_MS:g} ms, "
                                                     f"got {row[2]:g}")
            compute = float(row[2]) / 1000.0
        return VelocityCommand(float(row[0]) / 1000.0, math.radians(float(row[1])), compute)
    if verb == "A":
        return AuthCommand(_secret(rest, "A"))
    if verb == "L":
        return LeaseCommand(None if rest is None or not rest.strip() else _secret(rest, "L"))
    raise ProtocolError(ErrorCode.UNSUPPORTED, f"unknown command T,T,{verb[:10]}")


def _moving(rest: str | None, field_size: tuple[float, float] | None) -> MovingCommand:
    """``T,T,M`` arguments: per obstacle ``radius,speed,repeat,delay,x1,y1,...`` (mm, mm/s, code, s, mm)."""
    if rest is None or not rest.strip():
        return MovingCommand(())
    items = rest.split(";")
    if len(items) > MAX_MOVING:
        raise ProtocolError(ErrorCode.RANGE, f"too many moving obstacles: {len(items)} > {MAX_MOVING}")
    out = []
    for i, item in enumerate(items):
        width = item.count(",") + 1
        if width < 6 or width % 2 or width > 4 + 2 * MAX_TRACK_POINTS:
            raise ProtocolError(ErrorCode.SYNTAX, f"obstacle {i + 1}: expected radius,speed,repeat,delay and 1 to "
                                                  f"{MAX_TRACK_POINTS} points x,y, got {width} fields")
        try:
            v = _parse_tuples(item, width, "obstacle", 1)[0]
        except ProtocolError as exc:  # it counts one item: name the obstacle
            raise ProtocolError(exc.code, f"obstacle {i + 1}{exc.message.partition(' 1')[2]}") from None
        if v[0] <= 0 or v[1] <= 0 or v[3] < 0 or v[2] not in (0.0, 1.0, 2.0):
            raise ProtocolError(ErrorCode.RANGE, f"obstacle {i + 1}: radius and speed must be > 0, delay >= 0 and "
                                                 "repeat 0 (once), 1 (loop) or 2 (pingpong)")
        pts = v[4:].reshape(-1, 2) / 1000.0
        _check_range(pts, field_size, f"obstacle {i + 1} point")
        out.append((np.array([v[0] / 1000.0, v[1] / 1000.0, v[2], v[3]]), pts))
    return MovingCommand(tuple(out))


def _name_error(name: str, what: str) -> str | None:
    if not name or len(name) > MAX_NAME_CHARS or not set(name) <= _NAME_CHARS:
        return f"{what} {name[:20]!r} is not a name (1 to {MAX_NAME_CHARS} of a-z, 0-9, _)"
    return None


def _controller(rest: str | None) -> ControllerCommand:
    """``T,T,C[,<name>[,k=v,...]]``; names are checked here, the controller and its values by the robot."""
    fields = [] if rest is None or not rest.strip() else [f.strip() for f in rest.split(",")]
    if not fields:
        return ControllerCommand(None, {})
    if len(fields) > MAX_CONTROLLER_PARAMS + 1:
        raise ProtocolError(ErrorCode.SYNTAX, f"T,T,C takes at most {MAX_CONTROLLER_PARAMS} parameters")
    why = _name_error(fields[0], "controller")
    if why:
        raise ProtocolError(ErrorCode.SYNTAX, why)
    params: dict[str, float] = {}
    for f in fields[1:]:
        key, eq, value = f.partition("=")
        key = key.strip()
        why = _name_error(key, "parameter") or (None if eq else f"parameter {key!r} needs a value: {key}=<number>")
        why = why or _number_error(value)
        if why is None and key in params:
            why = f"parameter {key!r} given twice"
        if why is None and not math.isfinite(float(value)):
            why = "numbers must be finite"
        if why:
            raise ProtocolError(ErrorCode.SYNTAX, why)
        params[key] = float(value)
    return ControllerCommand(fields[0], params)


def parse_command(line: str | bytes, *, field_size: tuple[float, float] | None = None) -> Command:
    """Parse one client line (terminator optional) into a command, SI units.

    ``field_size`` (metres) enables the RANGE checks of path points,
    placements and blocks.  Raises :class:`ProtocolError` for anything
    malformed.  Linear time in the length of the line, whatever it holds.
    """
    verb, rest = split_command(line)
    return parse_arguments(verb, rest, field_size=field_size)


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


def encode_controller(name: str | None, params: dict[str, float] | None = None) -> str:
    """The ``T,T,C`` line choosing controller ``name`` (None: the default) with ``params`` (their own units)."""
    if name is None:
        return "T,T,C"
    return ",".join(["T,T,C", name, *(f"{k}={float(v)!r}" for k, v in sorted((params or {}).items()))])


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


def encode_moving(obstacles: Iterable[tuple[Sequence[float], Sequence[Sequence[float]]]]) -> str:
    """``T,T,M`` line for moving obstacles given as (params, waypoints): params radius m, speed m/s, repeat
    code, delay s; waypoints ``(K, 2)`` m; none clears."""
    parts = []
    for par, pts in obstacles:
        p = _finite_2d([par], 4, "params")[0]
        w = _finite_2d(pts, 2, "waypoints")
        head = [_fmt(p[0] * 1000, 2), _fmt(p[1] * 1000, 2), str(int(p[2])), _fmt(p[3], 3)]
        parts.append(",".join(head + [_fmt(v * 1000, 2) for v in w.ravel().tolist()]))
    return "T,T,M," + ";".join(parts) if parts else "T,T,M"


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


def format_event(kind: Event | str, t: float, *, index: int | None = None, reason: str | None = None,
                 seconds: float | None = None) -> str:
    """``EV,START,t``, ``EV,WP,i,t``, ``EV,DONE,t`` or ``EV,FAIL,<reason>,t`` (t in seconds); a collision
    with moving obstacle ``index`` is ``EV,FAIL,COLLISION,OBSTACLE,<index>,t``; a replan
    ``EV,REPLAN,<index points>,<seconds as ms>,t`` (0 points: none found)."""
    k = Event(kind)
    ts = _fmt(t, 3)
    if k is Event.WP:
        if index is None:
            raise ValueError("`index` is required for WP events")
        return f"EV,WP,{index},{ts}"
    if k is Event.REPLAN:
        if index is None:
            raise ValueError("`index` is required for REPLAN events")
        return f"EV,REPLAN,{int(index)},{_fmt((seconds or 0.0) * 1000.0, 1)},{ts}"
    if k is Event.FAIL:
        if reason not in FAIL_REASONS:
            raise ValueError(f"`reason` must be one of {', '.join(FAIL_REASONS)}")
        if reason == "COLLISION" and index is not None:
            return f"EV,FAIL,COLLISION,OBSTACLE,{int(index)},{ts}"
        return f"EV,FAIL,{reason},{ts}"
    return f"EV,{k.value},{ts}"


def format_localisation(pose: Sequence[float], t: float) -> str:
    """``PO,<x>,<y>,<a>,<t>`` (mm, mm, deg, s) from a pose in metres/radians measured at ``t`` seconds."""
    return format_localisations(np.array([t], dtype=float), np.array([pose], dtype=float))[0]


def format_localisations(t: np.ndarray, poses: np.ndarray) -> list[str]:
    """The ``PO`` line (:func:`format_localisation`) of each pose ``(K, 3)`` (m, m, rad) measured at ``t``
    ``(K,)`` (s); the units are converted for all of them at once."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    mm = (p[:, :2] * 1000.0).tolist()
    deg = np.degrees(_wrap(p[:, 2])).tolist()
    return [f"PO,{_fmt(x, 2)},{_fmt(y, 2)},{_fmt(a, 3)},{_fmt(tt, 3)}"
            for (x, y), a, tt in zip(mm, deg, np.asarray(t, dtype=float).tolist())]


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
        """Experiment time (s) of ST, EV and PO lines, else None."""
        if self.kind in ("ST", "EV", "PO") and self.fields:
            try:
                return float(self.fields[-1])
            except ValueError:
                return None
        return None


_REPLY_KINDS = {"HELLO", "OK", "ST", "EV", "ERR", "PO"}


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
