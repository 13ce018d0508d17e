"""Where the emulated overhead tracker's poses go: CSV files, memory, or the server (HTTP).

A sink receives batches of one robot's logged poses as ``(M, 4)`` arrays of
``t, x, y, theta`` (experiment seconds, metres in the robot's frame,
radians).  :class:`TrackerSink` is the interface; :class:`CsvTrackerSink`
writes standalone files, :class:`MemoryTrackerSink` keeps them (tests, and a
server embedding agents in its own process), and
:class:`robot_agent.host.server_link.ServerLink` posts them to the testbed server.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["CsvTrackerSink", "MemoryTrackerSink", "TrackerSink", "csv_path_for"]


@runtime_checkable
class TrackerSink(Protocol):
    """Receives tracker pose batches; must not block the event loop."""

    async def send(self, robot_id: str, poses: np.ndarray) -> None:
        """Accept ``poses`` ``(M, 4)`` = t (s), x, y (m, robot frame), theta (rad) of ``robot_id``."""

    async def aclose(self) -> None:
        """Deliver what is pending (best effort) and release resources."""


class MemoryTrackerSink:
    """Keeps every batch in memory; :meth:`poses` returns a robot's poses so far."""

    def __init__(self) -> None:
        self._batches: dict[str, list[np.ndarray]] = {}

    async def send(self, robot_id: str, poses: np.ndarray) -> None:
        self._batches.setdefault(robot_id, []).append(np.array(poses, dtype=float))

    def poses(self, robot_id: str) -> np.ndarray:
        """All poses of ``robot_id`` received so far, ``(M, 4)``."""
        parts = self._batches.get(robot_id, [])
        return np.concatenate(parts) if parts else np.zeros((0, 4))

    def clear(self) -> None:
        """Forget everything received."""
        self._batches.clear()

    async def aclose(self) -> None:
        pass


def csv_path_for(pattern: str | Path, robot_id: str, many: bool) -> Path:
    """The CSV file of ``robot_id``: ``{robot_id}`` in ``pattern`` is replaced; otherwise, when a
    host has ``many`` robots, ``-<robot_id>`` is inserted before the suffix."""
    text = str(pattern)
    if "{robot_id}" in text:
        return Path(text.replace("{robot_id}", robot_id))
    p = Path(text)
    return p.with_name(f"{p.stem}-{robot_id}{p.suffix}") if many else p


class CsvTrackerSink:
    """Appends poses to one CSV file per robot, header ``t,x,y,theta`` (see :func:`csv_path_for`).

    Files are created (truncated) on the first batch; writes run in a thread.
    """

    def __init__(self, pattern: str | Path, *, many: bool = False) -> None:
        self.pattern = pattern
        self.many = many
        self._started: set[Path] = set()
        self._lock = asyncio.Lock()

    def path(self, robot_id: str) -> Path:
        """The file ``robot_id``'s poses go to."""
        return csv_path_for(self.pattern, robot_id, self.many)

    def _write(self, path: Path, poses: np.ndarray) -> None:
        fresh = path not in self._started
        with open(path, "w" if fresh else "a", encoding="ascii") as f:
            if fresh:
                f.write("t,x,y,theta\n")
            f.writelines(f"{t:.3f},{x:.6f},{y:.6f},{a:.6f}\n" for t, x, y, a in poses.tolist())
        self._started.add(path)

    async def send(self, robot_id: str, poses: np.ndarray) -> None:
        async with self._lock:  # keeps each file's batches in order
            await asyncio.to_thread(self._write, self.path(robot_id), np.asarray(poses, dtype=float))

    async def aclose(self) -> None:
        async with self._lock:
            pass
