"""The simulation core: steps all robots of a host at once (numpy, no loops over robots).

:class:`SimCore` holds the fleet's controller state (paths, current
waypoints, commands, stall anchors, timeouts), a :class:`~robot_agent.backends.Backend`
for the physical side and a :class:`~robot_agent.world.World` for frames and
collisions.  :meth:`SimCore.step` advances experiment time by one control
step (``1 / control_rate_hz``) and returns the events of that step; it does
no I/O.  The host (:mod:`robot_agent.host`) calls it from an asyncio task.

Experiment time is ``step_count x dt``.  Events are stamped with the time of
the step in which they were detected: START, WP, DONE, STALLED and TIMEOUT at
the step's start (when the controller sensed), COLLISION at its end.  Logged
tracker poses are collected in :attr:`SimCore.poses` (a :class:`PoseLog`).

Replay: a run's trajectory depends only on the pose it starts from (at
rest), its path, its noise key (see :mod:`robot_agent.noise`) and, in a
shared world, on the other robots; all noise is indexed by the control step
since the path began.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from .backends import Backend
from .follower import advance_waypoints, control_step, stall_update, timeout_steps
from .params import RobotParams
from .world import World

__all__ = ["SimCore", "SimEvent", "PoseLog", "State"]


class State(IntEnum):
    """Per-robot path state (the ``ST`` reply's names)."""

    IDLE = 0
    MOVING = 1
    DONE = 2
    FAILED = 3


@dataclass(frozen=True)
class SimEvent:
    """An event of robot ``robot`` at experiment time ``t`` (s).

    ``kind`` is START, WP, DONE or FAIL; ``index`` the path point of a WP
    (0-based); ``reason`` the FAIL reason (COLLISION, TIMEOUT, STALLED, STOPPED).
    """

    robot: int
    kind: str
    t: float
    index: int | None = None
    reason: str | None = None


class PoseLog:
    """Tracker poses collected step by step, drained per robot as ``(M, 4)`` arrays ``t, x, y, theta``."""

    def __init__(self) -> None:
        self._chunks: list[tuple[float, np.ndarray, np.ndarray]] = []
        self.count = 0

    def add(self, t: float, robots: np.ndarray, poses: np.ndarray) -> None:
        """Record ``poses`` ``(K, 3)`` of robot indices ``robots`` ``(K,)`` at time ``t`` (s)."""
        self._chunks.append((t, robots, poses))
        self.count += len(robots)

    def drain(self) -> dict[int, np.ndarray]:
        """All poses recorded since the last drain, per robot index, in time order."""
        if not self._chunks:
            return {}
        chunks, self._chunks, self.count = self._chunks, [], 0
        robots = np.concatenate([c[1] for c in chunks])
        t = np.concatenate([np.full(len(c[1]), c[0]) for c in chunks])
        rows = np.column_stack([t, np.concatenate([c[2] for c in chunks])])
        order = np.argsort(robots, kind="stable")
        robots, rows = robots[order], rows[order]
        cuts = np.flatnonzero(np.diff(robots)) + 1
        return {int(r[0]): block for r, block in zip(np.split(robots, cuts), np.split(rows, cuts))}


class SimCore:
    """Steps ``n`` robots sharing ``params`` through ``backend`` in ``world``."""

    def __init__(self, params: RobotParams, backend: Backend, world: World, *, log_poses: bool = True) -> None:
        n = backend.n
        self.n, self.params, self.backend, self.world = n, params, backend, world
        self.dt = params.dt
        world.step_travel = 2.0 * params.max_speed_m_s * self.dt  # generous bound: gains and noise stay far below 2x
        self.step_count = 0
        self.log_poses = log_poses
        self.poses = PoseLog()
        self.state = np.full(n, State.IDLE, dtype=np.int8)
        self.aligning = np.zeros(n, dtype=bool)
        self.wp = np.zeros(n, dtype=np.int64)
        self.k = np.zeros(n, dtype=np.int64)  # control steps since the path began
        self.timeout = np.zeros(n, dtype=np.int64)
        self.cmd = np.zeros((n, 2))
        self.anchor = np.zeros((n, 3))
        self.anchor_k = np.zeros(n, dtype=np.int64)
        self.keys = np.zeros(n, dtype=np.uint64)
        self._paths: list[np.ndarray] = [np.zeros((0, 3)) for _ in range(n)]
        self._dirty = True
        self._rebuild_paths()

    # ------------------------------------------------------------------ time

    @property
    def t(self) -> float:
        """Experiment time (s)."""
        return self.step_count * self.dt

    def busy(self) -> bool:
        """True while stepping changes anything (a path is followed or a robot still moves)."""
        return bool((self.state == State.MOVING).any()) or self.backend.busy()

    def skip(self, steps: int) -> None:
        """Advance the clock by ``steps`` without stepping (only valid when not :meth:`busy`)."""
        self.step_count += steps

    # ------------------------------------------------------------------ commands

    def belief(self, i: int) -> np.ndarray:
        """Robot ``i``'s believed pose (its own frame)."""
        return self.backend.belief[i].copy()

    def set_path(self, i: int, points: np.ndarray, key: int) -> SimEvent | None:
        """Robot ``i`` follows ``points`` ``(P, 3)`` (its frame, m/rad) from the next step.

        Returns the ``FAIL,STOPPED`` event of a path it replaces, if any.
        """
        replaced = self.stop(i)
        from_rest = np.zeros(self.n, dtype=bool)
        from_rest[i] = replaced is None
        self._paths[i] = np.asarray(points, dtype=float).reshape(-1, 3)
        self._dirty = True
        self.state[i] = State.MOVING
        self.aligning[i] = False
        self.wp[i] = 0
        self.k[i] = 0
        if replaced is None:
            self.cmd[i] = 0.0
        self.keys[i] = np.uint64(key)
        mask = np.zeros(self.n, dtype=bool)
        mask[i] = True
        self.backend.begin_path(mask, self.keys, from_rest)
        self.timeout[i] = timeout_steps(self._paths[i], self.belief(i), self.params.controller,
                                        self.params.max_speed_m_s, self.dt)
        return replaced

    def stop(self, i: int) -> SimEvent | None:
        """Stop robot ``i``'s path now; returns its ``FAIL,STOPPED`` event if it was moving."""
        if self.state[i] != State.MOVING:
            return None
        self.state[i] = State.FAILED
        self.cmd[i] = 0.0
        return SimEvent(i, "FAIL", self.t, reason="STOPPED")

    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        """Put robot ``i`` (not moving) at ``pose`` in its frame; its state becomes IDLE."""
        self.backend.place(i, pose)
        self.world.invalidate(i)
        self.state[i] = State.IDLE
        self.cmd[i] = 0.0

    def _rebuild_paths(self) -> None:
        counts = np.array([len(p) for p in self._paths], dtype=np.int64)
        self.count = counts
        self.offset = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        # robots without a path point at a dummy row at the end
        self.points = np.vstack([*self._paths, np.zeros((1, 3))])
        self.offset[counts == 0] = len(self.points) - 1
        self._dirty = False

    # ------------------------------------------------------------------ the step

    def step(self) -> list[SimEvent]:
        """Advance one control step; returns its events (usually none)."""
        if self._dirty:
            self._rebuild_paths()
        moving = self.state == State.MOVING
        if not moving.any() and not self.backend.busy():
            self.step_count += 1
            return []
        t0 = self.t
        p = self.params
        belief, logged, logged_pose = self.backend.sense(self.k, moving)
        if self.log_poses and logged.any():
            idx = np.flatnonzero(logged)
            self.poses.add(t0, idx, logged_pose[idx].copy())
        started = moving & (self.k == 0)
        if started.any():
            self.anchor[started] = belief[started]
            self.anchor_k[started] = 0
        old_wp = self.wp
        self.wp, arrived = advance_waypoints(belief, self.points, self.offset, self.count, old_wp,
                                             moving & ~self.aligning, p.controller)
        self.aligning |= arrived
        target = self.points[self.offset + self.wp]
        is_last = self.wp == self.count - 1
        cmd, aligned = control_step(belief, target, is_last, self.aligning, self.cmd, p.controller,
                                    p.max_speed_m_s, p.max_angular_speed_rad_s, self.dt)
        done = moving & aligned
        stalled = stall_update(belief, self.anchor, self.anchor_k, self.k, moving & ~done, p.controller, self.dt)
        timed_out = moving & ~done & ~stalled & (self.k >= self.timeout)
        ended = done | stalled | timed_out
        cmd[~moving | ended] = 0.0
        self.cmd = cmd
        self.backend.actuate(cmd)
        still = moving & ~ended
        collided = self.world.collisions(self.backend.pose, still | self.backend.in_motion(), self.step_count)
        if collided.any():
            self.backend.halt(collided)
            self.cmd[collided] = 0.0
        crashed = collided & still
        self.k += 1
        self.step_count += 1
        events: list[SimEvent] = []
        if started.any() or (self.wp != old_wp).any() or arrived.any() or ended.any() or crashed.any():
            events = self._events(t0, started, old_wp, arrived, done, stalled, timed_out, crashed)
        return events

    def _events(self, t0: float, started: np.ndarray, old_wp: np.ndarray, arrived: np.ndarray,
                done: np.ndarray, stalled: np.ndarray, timed_out: np.ndarray, crashed: np.ndarray) -> list[SimEvent]:
        """Event records of one step, in order per robot; updates the path states."""
        out: list[SimEvent] = []
        t1 = self.t
        for i in np.flatnonzero(started | (self.wp != old_wp) | arrived | done | stalled | timed_out | crashed):
            i = int(i)
            if started[i]:
                out.append(SimEvent(i, "START", t0))
            for w in range(int(old_wp[i]), int(self.wp[i])):
                out.append(SimEvent(i, "WP", t0, index=w))
            if arrived[i]:
                out.append(SimEvent(i, "WP", t0, index=int(self.wp[i])))
            if done[i]:
                self.state[i] = State.DONE
                out.append(SimEvent(i, "DONE", t0))
            elif stalled[i] or timed_out[i]:
                self.state[i] = State.FAILED
                out.append(SimEvent(i, "FAIL", t0, reason="STALLED" if stalled[i] else "TIMEOUT"))
            elif crashed[i]:
                self.state[i] = State.FAILED
                out.append(SimEvent(i, "FAIL", t1, reason="COLLISION"))
        return out
