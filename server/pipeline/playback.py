"""A run computed ahead as a task, played out at the testbed's time scale: shown live, logged as it happens.

A multi-robot run, or a field run with profile overrides, is computed in
one task (:mod:`.fleet`, :mod:`.remote`) in a fraction of its experiment
time.  On a robot's slot it still takes its time, as a run on an agent's
robot does: its sub-field (or the field) is held for the experiment time
at the time scale, every robot's poses are shown as they come due, and
the protocol lines go to the log at their time.  A run cancelled (or a
testbed stopped) part way keeps what was played until then, and no more.

:class:`Playback` is pure bookkeeping over arrays; :func:`play` adds the
clock, :func:`play_run` the run's tracker and log.
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Any, Awaitable, Callable, Optional, Sequence

import numpy as np

from .context import RunContext, RunServices

__all__ = ["Line", "Playback", "play", "play_run"]

#: a protocol line as a task returns it: direction, text, experiment time s (None: not timed)
Line = tuple[str, str, Optional[float]]

#: wall seconds between two showings (the tracker publishes a robot's pose at most every 0.1 s)
TICK_S = 0.1


class Playback:
    """Tracks ``(N_k, 4)`` (t s, x m, y m, theta rad; each in time order) and lines, released up to an
    experiment time that only moves forward."""

    def __init__(self, tracks: Sequence[np.ndarray], lines: Sequence[Line] = ()) -> None:
        self.tracks = [np.asarray(tr, dtype=float).reshape(-1, 4) for tr in tracks]
        firsts = [float(tr[0, 0]) for tr in self.tracks if len(tr)]
        #: experiment time of the first pose (s), where playing starts
        self.t_first = min(firsts) if firsts else 0.0
        #: experiment time of the last pose (s), where it ends
        self.t_last = max((float(tr[-1, 0]) for tr in self.tracks if len(tr)), default=self.t_first)
        self._lines, self._line_t = _timed(lines)
        self._shown = [0] * len(self.tracks)
        self._logged = 0
        #: experiment time released so far (s)
        self.t = -math.inf

    def advance(self, t: float) -> tuple[list[tuple[int, np.ndarray]], list[Line]]:
        """Release everything up to experiment time ``t`` (s): the new rows of each track that has some, as
        ``(index, rows)``, and the lines now due, in time order."""
        self.t = max(self.t, t)
        rows = []
        for k, tr in enumerate(self.tracks):
            n = int(np.searchsorted(tr[:, 0], self.t, side="right"))
            if n > self._shown[k]:
                rows.append((k, tr[self._shown[k]:n]))
                self._shown[k] = n
        m = int(np.searchsorted(self._line_t, self.t, side="right"))
        lines, self._logged = self._lines[self._logged:m], max(self._logged, m)
        return rows, lines

    def played(self, k: int) -> np.ndarray:
        """Track ``k``'s rows released so far."""
        return self.tracks[k][:self._shown[k]]

    def ended(self, k: int) -> bool:
        """Whether track ``k`` is released to its last row."""
        return self._shown[k] == len(self.tracks[k])

    def until_played(self, tracks: Optional[Sequence[np.ndarray]]) -> Optional[list[np.ndarray]]:
        """Other tracks ``(T, 4)`` on the same clock (a field run's obstacle robots) cut where playing has
        got to: their rows up to the experiment time released (None stays None)."""
        if tracks is None:
            return None
        out = []
        for tr in tracks:
            tr = np.asarray(tr, dtype=float).reshape(-1, 4)
            out.append(tr[:int(np.searchsorted(tr[:, 0], self.t, side="right"))])
        return out

    @property
    def done(self) -> bool:
        return self.t >= self.t_last and self._logged == len(self._lines)


def _timed(lines: Sequence[Line]) -> tuple[list[Line], np.ndarray]:
    """The lines in time order (stable) and their times: an untimed line takes the time of the line before
    it (the first ones: before everything)."""
    at, t = [], -math.inf
    for _, _, lt in lines:
        t = lt if lt is not None else t
        at.append(t)
    order = np.argsort(np.asarray(at, dtype=float), kind="stable") if at else np.zeros(0, dtype=int)
    return [lines[i] for i in order], np.asarray(at, dtype=float)[order] if at else np.zeros(0)


async def play(playback: Playback, time_scale: float, show: Callable[[int, np.ndarray, bool], None],
               log: Callable[[Line], None], flush: Optional[Callable[[], Awaitable[Any]]] = None) -> None:
    """Release ``playback`` as its experiment time passes at ``time_scale`` (experiment s per wall s; inf:
    at once): new rows to ``show(k, rows, last)`` (``last``: they end track ``k``), due lines to
    ``log(line)``, then ``flush()`` (storing the log so far) about once a second.  Cancelling it leaves
    ``playback`` at what was released."""
    wall0 = flushed = time.monotonic()
    while True:
        now = time.monotonic()
        t = math.inf if math.isinf(time_scale) else playback.t_first + (now - wall0) * time_scale
        _release(playback, *playback.advance(t), show, log)
        if playback.done:
            return
        if flush is not None and now - flushed >= 1.0:
            await flush()
            flushed = now
        await asyncio.sleep(TICK_S)


def _release(playback: Playback, rows: list[tuple[int, np.ndarray]], lines: list[Line],
             show: Callable[[int, np.ndarray, bool], None], log: Callable[[Line], None]) -> None:
    for line in lines:
        log(line)
    for k, r in rows:
        show(k, r, playback.ended(k))


async def play_run(ctx: RunContext, svc: RunServices, owner_id: int, playback: Playback, *, fleet: bool) -> None:
    """Play a run's computed poses (``fleet``: track k is fleet member k's) and lines on its robot's slot at
    the time scale (on a compute engine's slot, at once, as its single-robot runs are): shown through the
    tracker, logged, the log stored about once a second."""
    robot_id, run_id = ctx.robot.robot_id, ctx.run_id
    await play(playback, math.inf if ctx.robot.engine else ctx.time_scale,
               lambda k, rows, last: svc.tracker.show(robot_id, run_id, owner_id, rows,
                                                      member=k if fleet else None, last=last),
               lambda line: ctx.on_line(line[0], line[1], line[2], False),
               lambda: svc.recorder.add_messages(ctx.take_messages()))
