"""Tracker pose ingestion: routes each robot's pose batches to the run it is executing.

The tracker (emulated overhead cameras, or ground truth in the simulation
pool) streams every robot's poses all the time, as on the real testbed; the
runner opens a *window* on a robot for the run it executes, and only poses
inside an open window are stored.  Live positions of every robot are
published for the dashboard, at most a few per second per robot.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from .broker import EventBroker
from .errors import Invalid
from .store.poses import insert_poses

__all__ = ["PoseRouter", "parse_batch"]

_LIVE_INTERVAL_S = 0.1


@dataclass
class _Window:
    run_id: int
    owner_id: int
    stored: int = 0


class PoseRouter:
    """Which run each robot's poses belong to, and the store for them."""

    def __init__(self, sessions: sessionmaker[Session], broker: EventBroker,
                 origin_of: Callable[[str], tuple[float, float]]) -> None:
        self._sessions = sessions
        self._engine = sessions.kw["bind"]
        self._broker = broker
        self._origin_of = origin_of
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._windows: dict[str, _Window] = {}
        self._last_t: dict[str, float] = {}
        self._last_live: dict[str, float] = {}
        self._last_pose: dict[str, list[float]] = {}
        self._waiters: dict[str, list[tuple[float, asyncio.Future, asyncio.AbstractEventLoop]]] = {}
        self.dropped = 0

    def open(self, robot_id: str, run_id: int, owner_id: int) -> None:
        """Store ``robot_id``'s poses for ``run_id`` from now on."""
        with self._lock:
            self._windows[robot_id] = _Window(run_id, owner_id)

    def window_owner(self, robot_id: str) -> Optional[int]:
        """The owner of the run whose window is open on ``robot_id`` (None: the robot runs nobody's)."""
        with self._lock:
            w = self._windows.get(robot_id)
        return w.owner_id if w else None

    def close(self, robot_id: str) -> int:
        """Stop storing; returns how many poses the window stored."""
        with self._lock:
            w = self._windows.pop(robot_id, None)
        return w.stored if w else 0

    def last_time(self, robot_id: str) -> Optional[float]:
        return self._last_t.get(robot_id)

    def last_pose(self, robot_id: str) -> Optional[list[float]]:
        """The robot's last tracked pose ``[t, x, y, theta]`` in field coordinates, if any."""
        return self._last_pose.get(robot_id)

    def place(self, robot_id: str, pose: tuple[float, float, float, float]) -> None:
        """Where the tracker sees ``robot_id`` when it joins, ``(t, x, y, theta)`` in its own frame (s, m, rad):
        its last pose from now on, published live, unless a run's window is open on it (the run's poses
        are newer). Not stored, and no waiter is woken: it is no run's pose."""
        with self._lock:
            if robot_id in self._windows:
                return
        t, x, y, a = pose
        ox, oy = self._origin_of(robot_id)
        self._last_pose[robot_id] = [t, x + ox, y + oy, a]
        self._publish(robot_id, None, t, x + ox, y + oy, a)

    async def wait_for_time(self, robot_id: str, t: float, timeout_s: float) -> bool:
        """Wait until a pose of ``robot_id`` at experiment time >= ``t`` has arrived (or time out)."""
        loop = asyncio.get_running_loop()
        fut: asyncio.Future = loop.create_future()
        with self._lock:
            if self._last_t.get(robot_id, -float("inf")) >= t:
                return True
            self._waiters.setdefault(robot_id, []).append((t, fut, loop))
        try:
            await asyncio.wait_for(fut, timeout_s)
            return True
        except asyncio.TimeoutError:
            return False
        finally:
            with self._lock:
                self._waiters[robot_id] = [w for w in self._waiters.get(robot_id, []) if w[1] is not fut]

    def ingest(self, robot_id: str, rows: np.ndarray) -> tuple[int, Optional[int]]:
        """Accept one batch ``(N, 4)`` of ``t, x, y, theta``; returns (stored, run_id). Thread-safe, blocking I/O."""
        if len(rows) == 0:
            return 0, None
        with self._lock:
            w = self._windows.get(robot_id)
        stored = 0
        if w is not None:
            insert_poses(self._engine, w.run_id, rows, lock=self._write_lock)
            stored = len(rows)
            with self._lock:
                w.stored += stored
        else:
            self.dropped += len(rows)
        self._seen(robot_id, rows, w)
        return stored, (w.run_id if w else None)

    def show(self, robot_id: str, run_id: int, owner_id: int, rows: np.ndarray, member: Optional[int] = None,
             last: bool = True) -> None:
        """Poses ``(N, 4)`` of a run that are stored with its end (a compute engine's run): known as the
        robot's last pose and shown live, not stored here.  ``member``: the poses are fleet member
        ``member``'s of a multi-robot run on ``robot_id``: known and shown as robot ``"<robot_id>/<member>"``
        (in ``robot_id``'s frame), the live event also carrying ``"robot": member``.  ``last``: the rows end
        the run's poses, so the live event goes out whenever the one before it did (the robot is shown
        where it stopped)."""
        if len(rows):
            self._seen(robot_id, rows, _Window(run_id, owner_id), member, force=last)

    def _seen(self, robot_id: str, rows: np.ndarray, w: Optional[_Window], member: Optional[int] = None,
              force: bool = False) -> None:
        """The robot's last pose and time, its waiters woken, and a live event (at most every 0.1 s unless
        ``force``)."""
        last = float(rows[:, 0].max())
        t_last, x_last, y_last, a_last = (float(v) for v in rows[-1])
        ox, oy = self._origin_of(robot_id)
        if member is not None:
            robot_id = f"{robot_id}/{member}"
        self._last_pose[robot_id] = [t_last, x_last + ox, y_last + oy, a_last]
        wake = []
        with self._lock:
            self._last_t[robot_id] = max(self._last_t.get(robot_id, -float("inf")), last)
            for t, fut, loop in self._waiters.get(robot_id, []):
                if last >= t:
                    wake.append((fut, loop))
        for fut, loop in wake:
            loop.call_soon_threadsafe(lambda f=fut: f.done() or f.set_result(True))
        now = time.monotonic()
        if force or now - self._last_live.get(robot_id, 0.0) >= _LIVE_INTERVAL_S:
            self._last_live[robot_id] = now
            self._publish(robot_id, w, t_last, x_last + ox, y_last + oy, a_last, member)

    def _publish(self, robot_id: str, w: Optional[_Window], t: float, x: float, y: float, theta: float,
                 member: Optional[int] = None) -> None:
        """A live ``pose`` event: ``robot_id`` at (x, y, theta) (field frame; m, rad) at experiment time ``t``
        (s), of the run of window ``w`` (None: no run's); ``member`` a fleet member's index."""
        event = {"type": "pose", "robot_id": robot_id, "run_id": w.run_id if w else None,
                 "owner_id": w.owner_id if w else None, "t": t, "x": x, "y": y, "theta": theta}
        if member is not None:
            event["robot"] = member
        self._broker.publish(event)


def parse_batch(raw: bytes) -> tuple[str, np.ndarray, int]:
    """``robot_id``, the valid rows ``(N, 4)`` and the number of rows of a tracker batch (JSON bytes).

    Raises :class:`~server.errors.Invalid` naming what is wrong with the batch
    as a whole; rows that are not four finite numbers (``true`` is not a
    number) are left out.
    """
    try:
        doc = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise Invalid(f"body is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise Invalid("body must be a JSON object {robot_id, poses}")
    robot_id, poses = doc.get("robot_id"), doc.get("poses")
    if not isinstance(robot_id, str) or not 1 <= len(robot_id) <= 64:
        raise Invalid("robot_id: must be a string of 1 to 64 characters")
    if not isinstance(poses, list):
        raise Invalid("poses: must be a list of [t, x, y, theta] rows")
    if len(poses) > 100_000:
        raise Invalid("poses: at most 100000 rows per batch")
    arr = None
    if _only_numbers_after_poses(raw):  # the common case, decided on the bytes: no booleans, strings or null
        try:
            arr = np.array(poses, dtype=float)
        except (ValueError, TypeError):  # ragged rows
            arr = None
        if arr is not None and (arr.ndim != 2 or arr.shape[1] != 4):
            arr = None
    if arr is None:  # the slow path: keep the rows of four numbers (true, "1" and null are not numbers)
        arr = np.array([r for r in poses if type(r) is list and len(r) == 4 and all(type(v) in (int, float) for v in r)],
                       dtype=float)
    arr = arr.reshape(-1, 4)
    return robot_id, arr[np.isfinite(arr).all(axis=1)], len(poses)


#: every byte a JSON array of numbers may hold (with Python's NaN, Infinity), and whitespace
_NUMERIC_JSON = bytes(b"0123456789+-.eE,[] \t\r\nNaInfity")


def _only_numbers_after_poses(raw: bytes) -> bool:
    """Whether everything from ``"poses"``'s array to the end of the body is numbers, brackets and commas
    (then a conversion cannot have turned ``true`` or ``"1"`` into a number).  An object whose
    ``robot_id`` comes after its poses just takes the exact, slower path."""
    at = raw.find(b'"poses"')
    start = raw.find(b"[", at) if at >= 0 else -1
    end = raw.rfind(b"]")
    return 0 <= start < end and not raw[start:end + 1].translate(None, _NUMERIC_JSON)
