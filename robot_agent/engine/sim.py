"""The simulation core: steps all robots of a host at once, no I/O.

:class:`SimCore` holds the fleet's path-follower state (paths, current
waypoints, commands, stall anchors, timeouts), a :class:`~robot_agent.engine.backends.Backend`
for the physical side and a :class:`~robot_agent.engine.world.World` for frames and
collisions.  :meth:`SimCore.advance` moves experiment time on by up to a
given number of control steps (``1 / control_rate_hz`` each) and returns the
events of those steps; :meth:`SimCore.step` does one.  The host
(:mod:`robot_agent.host`) calls them from an asyncio task.

With an emulated backend (ideal or field) the steps run inside compiled code
(:func:`robot_agent.engine.stepper.run`), many per call; any other backend (a real
robot) is stepped through its Python methods, with the same compiled
follower.  Both orders of work are the same: sense, follow, actuate, then
collisions once every robot moved.

Experiment time is ``step_count x dt``.  Events are stamped with the time of
the step in which they were detected: START, WP, DONE, STALLED and TIMEOUT at
the step's start (when the controller sensed), COLLISION at its end.  Logged
tracker poses are collected in :attr:`SimCore.poses` (a :class:`PoseLog`).

Replay: a run's trajectory depends only on the pose it starts from (at
rest), its path, its noise key (see :mod:`robot_agent.engine.noise`) and, in a
shared world, on the other robots; all noise is indexed by the control step
since the path began.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

from contract.controller_specs import Selection
from contract.params import RobotParams
from contract.protocol import format_event

from .backends import Backend, Emulated
from .controllers import DIRECT, MEMORY, PARAM_SLOTS, SCHEMA, project
from .follower import ARRIVED, DONE, STALLED, STARTED, TIMED_OUT, gains, timeout_steps
from .movers import drive_movers, drive_shared, mover_gains
from .stepper import COLLIDED, ENDED, FIELD, State, control_fleet, run, settle_fleet
from .world import World

if TYPE_CHECKING:
    from planners.environment import Environment

    from .replan import Replanner, Request, Result

__all__ = ["SimCore", "SimEvent", "PoseLog", "State"]

_MOVING = int(State.MOVING)  # a plain int: numpy scalars compare with it faster than with the enum member


@dataclass(frozen=True)
class SimEvent:
    """An event of robot ``robot`` at experiment time ``t`` (s).

    ``kind`` is START, WP, REPLAN, DONE or FAIL; ``index`` the path point of
    a WP (0-based), of a ``FAIL,COLLISION`` the moving obstacle hit (None:
    a block, a wall or a robot), of a REPLAN the new path's number of points
    (0: none was found); ``reason`` the FAIL reason (COLLISION, TIMEOUT,
    STALLED, STOPPED); ``seconds`` the wall time a REPLAN took (not compared:
    it is the machine's, not the run's).
    """

    robot: int
    kind: str
    t: float
    index: int | None = None
    reason: str | None = None
    seconds: float | None = field(default=None, compare=False)

    @property
    def line(self) -> str:
        """The ``EV`` line of this event (docs/protocol.md)."""
        return format_event(self.kind, self.t, index=self.index, reason=self.reason, seconds=self.seconds)


class PoseLog:
    """Tracker poses collected step by step, drained per robot as ``(M, 4)`` arrays ``t, x, y, theta``."""

    def __init__(self) -> None:
        self._chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.count = 0
        #: called with every batch as it is recorded (the host's localisation lines, ``T,T,O``)
        self.listener: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None

    def add(self, t: np.ndarray, robots: np.ndarray, poses: np.ndarray) -> None:
        """Record poses ``(K, 3)`` of robot indices ``robots`` ``(K,)`` at times ``t`` ``(K,)`` (s)."""
        self._chunks.append((t, robots, poses))
        self.count += len(robots)
        if self.listener is not None:
            self.listener(t, robots, poses)

    def clear(self) -> None:
        """Forget the poses recorded since the last drain."""
        self._chunks, self.count = [], 0

    def drain(self) -> dict[int, np.ndarray]:
        """All poses recorded since the last drain, per robot index, in time order."""
        if not self._chunks:
            return {}
        chunks, self._chunks, self.count = self._chunks, [], 0
        robots = np.concatenate([c[1] for c in chunks])
        rows = np.column_stack([np.concatenate([c[0] for c in chunks]), np.concatenate([c[2] for c in chunks])])
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
        self.gains = gains(params)
        world.step_travel = 2.0 * params.max_speed_m_s * self.dt  # generous bound: gains and noise stay far below 2x
        self._field = isinstance(backend, Emulated) and backend.kind == FIELD
        if self._field:  # on the emulated field moving obstacles are robots the testbed drives
            world.drive(params)
        self.mover_gains = mover_gains(params)
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
        self.cid = np.full(n, SCHEMA, dtype=np.int64)  # each robot's controller (robot_agent.engine.controllers)
        self.cpar = np.zeros((n, PARAM_SLOTS))
        self.cmem = np.zeros((n, MEMORY))
        self.want = np.zeros((n, 2))  # a plug-in controller's commands of this step
        self._plugins: dict[int, Selection] = {}  # robots whose controller runs in Python
        self._paths: list[np.ndarray] = [np.zeros((0, 3)) for _ in range(n)]
        # output buffers of the compiled loop; it stops when another step might not fit
        self._events = np.zeros((4 * n + 1024, 5), dtype=np.int64)
        self._pose_rows = np.zeros((4 * n + 4096, 2), dtype=np.int64)
        self._pose_xyt = np.zeros((len(self._pose_rows), 3))
        self._scratch = (np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool),
                         np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), np.zeros(3))
        self._dirty = True
        self._rebuild_paths()
        #: replanning robots' state (robot_agent.engine.replan), made with the first path that replans
        self.replanner: "Replanner | None" = None
        #: True: :meth:`advance` replans itself when a check is due; False: it stops there and the caller
        #: runs :meth:`replan_requests` / :func:`robot_agent.engine.replan.solve` / :meth:`apply_replan` (an agent,
        #: which plans in a worker thread)
        self.inline_replan = True
        self._maps: dict[int, "Environment"] = {}  # replanning robots' static maps of their current path

    # ------------------------------------------------------------------ time

    @property
    def t(self) -> float:
        """Experiment time (s)."""
        return self.step_count * self.dt

    def busy(self) -> bool:
        """True while stepping changes anything (a path is followed or a robot still moves)."""
        return bool((self.state == _MOVING).any()) or self.backend.busy()

    def skip(self, steps: int) -> None:
        """Advance the clock by ``steps`` without stepping the robots (only valid when not :meth:`busy`); a
        fleet's obstacle robots drive on."""
        if self._field and self.world.mo_first[-1] > self.world.mo_first[-2]:
            drive_shared(steps, self.k, self.world.arrays, self.world.tables, self.world.movers.arrays,
                         self.backend.fg, self.mover_gains)
        self.step_count += steps

    # ------------------------------------------------------------------ commands

    def belief(self, i: int) -> np.ndarray:
        """Robot ``i``'s believed pose (its own frame)."""
        return self.backend.belief[i].copy()

    def set_path(self, i: int, points: np.ndarray, key: int, controller: Selection | None = None) -> SimEvent | None:
        """Robot ``i`` follows ``points`` ``(P, 3)`` (its frame, m/rad) from the next step with ``controller``
        (:func:`contract.controller_specs.select`; None: the motor schema).

        Returns the ``FAIL,STOPPED`` event of a path it replaces, if any.
        """
        replaced = self.stop(i)
        from_rest = np.zeros(self.n, dtype=bool)
        from_rest[i] = replaced is None
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        self._paths[i] = pts
        if not self._dirty and 0 < len(pts) == self.count[i]:  # as long as the old one: in place, no rebuild
            self.points[self.offset[i]:self.offset[i] + len(pts)] = pts
        else:
            self._dirty = True
        self.state[i] = State.MOVING
        self.aligning[i] = False
        self.wp[i] = 0
        self.k[i] = 0
        if replaced is None:
            self.cmd[i] = 0.0
        self.keys[i] = np.uint64(key)
        self.cid[i] = SCHEMA if controller is None else controller.spec.cid
        self.cpar[i] = 0.0 if controller is None else controller.row
        self.cmem[i] = 0.0
        self.want[i] = 0.0
        self._plugins.pop(i, None)
        if controller is not None and not controller.spec.compiled:
            self._plugins[i] = controller
        mask = np.zeros(self.n, dtype=bool)
        mask[i] = True
        self.backend.begin_path(mask, self.keys, from_rest)
        self.world.restart_movers(i, key)
        self.timeout[i] = timeout_steps(self._paths[i], self.belief(i), self.params)
        self._begin_replanning(i, controller)
        return replaced

    def _begin_replanning(self, i: int, controller: Selection | None) -> None:
        """Robot ``i``'s new path replans when its controller says so (:mod:`robot_agent.engine.replan`)."""
        self._maps.pop(i, None)
        if self.replanner is None and (controller is None or not controller.replans):
            return
        from .replan import Replanner, Settings  # planners load only where a robot replans

        if self.replanner is None:
            self.replanner = Replanner(self.n, self.dt)
        self.replanner.begin(i, Settings.of(controller, self.params.max_speed_m_s), self.step_count)

    def drive(self, i: int, v: float, w: float, key: int, watchdog_s: float) -> SimEvent | None:
        """Robot ``i`` drives with body velocities ``(v, w)`` (m/s, rad/s; clipped to the profile's top speeds)
        until the next call, :meth:`stop` or ``watchdog_s`` of experiment time without a call (then
        ``FAIL,WATCHDOG``).  The first call starts velocity mode (a ``START``); returns the ``FAIL,STOPPED`` of
        a path it replaces, if any."""
        replaced = None
        if not self.driving(i):
            pose = self.belief(i)
            replaced = self.set_path(i, pose[None, :], key)
            self.cid[i] = DIRECT
        p = self.params
        self.want[i] = (min(max(float(v), -p.max_speed_m_s), p.max_speed_m_s),
                        min(max(float(w), -p.max_angular_speed_rad_s), p.max_angular_speed_rad_s))
        self.timeout[i] = self.k[i] + max(1, int(round(watchdog_s / self.dt)))
        return replaced

    def drive_from_rest(self, rows: np.ndarray, vw: np.ndarray, keys: np.ndarray, watchdog_s: float) -> None:
        """:meth:`drive` for robots ``rows`` at once, none of them moving: velocity mode begins for each with
        its noise key ``keys[i]`` and body velocities ``vw[i]`` (``(N, 2)`` and ``(N,)`` over all robots; m/s,
        rad/s), the watchdog ``watchdog_s`` (s).  The same state as one :meth:`drive` call per robot."""
        rows = np.asarray(rows, dtype=np.int64)
        if not len(rows):
            return
        if (self.state[rows] == _MOVING).any():
            raise ValueError("`rows` must not be moving robots (stop them first)")
        start = self.backend.belief[rows].copy()  # the one-point path of velocity mode, as drive() makes it
        for j, i in enumerate(rows.tolist()):
            self._paths[i] = start[j:j + 1]
            self._plugins.pop(i, None)
        if not self._dirty and (self.count[rows] == 1).all():
            self.points[self.offset[rows]] = start
        else:
            self._dirty = True
        self.state[rows] = State.MOVING
        self.aligning[rows] = False
        self.wp[rows] = 0
        self.k[rows] = 0
        self.cmd[rows] = 0.0
        self.keys[rows] = np.asarray(keys, dtype=np.uint64)[rows]
        self.cid[rows] = DIRECT
        self.cpar[rows] = 0.0
        self.cmem[rows] = 0.0
        self.want[rows] = 0.0
        mask = np.zeros(self.n, dtype=bool)
        mask[rows] = True
        self.backend.begin_path(mask, self.keys, mask)
        w = self.world
        for i in rows.tolist():
            if w.mo_first[i + 1] > w.mo_first[i]:
                w.restart_movers(i, int(self.keys[i]))
            if self.replanner is not None or self._maps:
                self._begin_replanning(i, None)
        self.drive_all(vw, watchdog_s)

    def drive_all(self, vw: np.ndarray, watchdog_s: float) -> None:
        """:meth:`drive` for every robot already in velocity mode at once: body velocities ``vw`` ``(N, 2)``
        (m/s, rad/s; clipped to the profile's top speeds as :meth:`drive` clips them) from the next step, the
        watchdog renewed to ``watchdog_s`` (s); rows of the other robots are ignored."""
        d = (self.state == _MOVING) & (self.cid == DIRECT)
        p = self.params
        top = np.array([p.max_speed_m_s, p.max_angular_speed_rad_s])
        np.copyto(self.want, np.clip(np.asarray(vw, dtype=float).reshape(self.n, 2), -top, top), where=d[:, None])
        np.copyto(self.timeout, self.k + max(1, int(round(watchdog_s / self.dt))), where=d)

    def moving(self, i: int) -> bool:
        """Whether robot ``i`` follows a path or drives in velocity mode (state MOVING)."""
        return self.state.item(i) == _MOVING

    def driving(self, i: int) -> bool:
        """Whether robot ``i`` is in velocity mode (:meth:`drive`)."""
        return self.state.item(i) == _MOVING and self.cid.item(i) == DIRECT

    def stop(self, i: int) -> SimEvent | None:
        """Stop robot ``i``'s path now; returns its ``FAIL,STOPPED`` event if it was moving."""
        if not self.moving(i):
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
        self.points = np.ascontiguousarray(np.vstack([*self._paths, np.zeros((1, 3))]))
        self.offset[counts == 0] = len(self.points) - 1
        self._dirty = False

    # ------------------------------------------------------------------ stepping

    def step(self) -> list[SimEvent]:
        """Advance one control step; returns its events (usually none)."""
        if not self.busy():
            self.step_count += 1
            return []
        return self.advance(1)

    def advance(self, max_steps: int) -> list[SimEvent]:
        """Advance up to ``max_steps`` control steps, stopping early once nothing moves any more
        (then :meth:`busy` is false); returns the events of those steps in order."""
        events: list[SimEvent] = []
        left = int(max_steps)
        while left > 0 and self.busy():
            chunk = left
            check = self._next_check()
            if check is not None:
                if check <= self.step_count:
                    if not self.inline_replan:
                        break  # the caller replans (replan_pending)
                    events += self.replan()
                    continue
                chunk = min(left, check - self.step_count)
            if self._dirty:
                self._rebuild_paths()
            if isinstance(self.backend, Emulated) and not self._plugin_moving():
                steps, n_ev, n_pose = run(
                    self.backend.kind, chunk, self.step_count, self.log_poses, self._ctrl(), self.backend.arrays,
                    self.world.arrays, self.world.radius, self.world.step_travel,
                    (self._events, self._pose_rows, self._pose_xyt, *self._scratch), self.gains, self.backend.fg,
                    self._movers(), self.mover_gains)
                if n_pose:
                    rows = self._pose_rows[:n_pose]
                    self.poses.add(rows[:, 0] * self.dt, rows[:, 1].copy(), self._pose_xyt[:n_pose].copy())
                records = self._events[:n_ev]
            else:
                steps, records = 1, self._python_step()
            self.step_count += steps
            left -= steps
            if len(records):
                events += self._records_to_events(records)
        return events

    def _movers(self) -> tuple:
        """``(tables, phys)`` of the world's obstacle robots for the compiled loop (the backend's arrays stand in
        when obstacles are exact: never touched then)."""
        movers = self.world.movers
        return self.world.tables, (movers.arrays if movers is not None else self.backend.arrays)

    # ------------------------------------------------------------------ replanning

    def _next_check(self) -> int | None:
        """The step of the next replanning check of a moving robot, None when no moving robot replans."""
        if self.replanner is None or not self.replanner.settings:
            return None
        return self.replanner.next_step(self.state == _MOVING)

    def replan_pending(self) -> bool:
        """Whether a replanning check is due now (:meth:`advance` stopped there when not ``inline_replan``)."""
        check = self._next_check()
        return check is not None and check <= self.step_count

    def replan_requests(self) -> list["Request"]:
        """Check the path ahead of every robot whose check is due now; the replans of those it finds
        blocked (cheap: numpy over the samples ahead; :mod:`robot_agent.engine.replan`)."""
        from .replan import Request, blocked, path_ahead, standing, static_map

        rp, world = self.replanner, self.world
        if rp is None:
            return []
        out = []
        belief = self.backend.belief
        for i in rp.due(self.step_count, self.state == _MOVING):
            if self.aligning[i] or not rp.may_replan(i, self.step_count):
                continue
            s = rp.settings[i]
            if self.cid[i] == SCHEMA:  # the schema keeps no projection: the robot's, from the leg it drives
                seg, frac = project(float(belief[i, 0]), float(belief[i, 1]), self._paths[i],
                                    max(int(self.wp[i]) - 1, 0), 0.0)
            else:
                seg, frac = int(self.cmem[i, 0]), float(self.cmem[i, 1])
            ahead, dist = path_ahead(self._paths[i], seg, frac, s.horizon_s * s.speed_m_s)
            env = self._maps.get(i)
            if env is None:
                env = self._maps[i] = static_map(world.area[i], world.world_blocks_local(i), world.moving_local(i))
            same = np.flatnonzero((world.world_of == world.world_of[i]) & (np.arange(self.n) != i))
            others = belief[same, :2] + world.origin[same] - world.origin[i]
            t_obs = float(self.k[i]) * self.dt
            if blocked(ahead, dist / s.speed_m_s, env.moving_obstacles, t_obs, others, world.radius):
                goal = self._paths[i][-1]
                out.append(Request(i, int(rp.generation[i]), env, world.radius, (float(belief[i, 0]),
                                   float(belief[i, 1])), (float(goal[0]), float(goal[1]), float(goal[2])), t_obs,
                                   standing(others, world.radius)))
        return out

    def apply_replan(self, req: "Request", res: "Result") -> SimEvent | None:
        """Follow a replan's new path from the next step (when the robot still follows the path it was
        planned for); the ``REPLAN`` event (0 points when none was found), or None when it came too late."""
        rp, i = self.replanner, req.robot
        if rp is None or rp.generation[i] != req.generation or not self.moving(i) or self.aligning[i]:
            return None
        rp.last[i] = self.step_count
        if res.path is None:
            return SimEvent(i, "REPLAN", self.t, index=0, seconds=res.seconds)
        points = np.ascontiguousarray(res.path, dtype=float).reshape(-1, 3)
        self._paths[i] = points
        self._dirty = True
        self.wp[i] = 0
        self.cmem[i] = 0.0
        self.timeout[i] = max(int(self.timeout[i]), int(self.k[i]) + timeout_steps(points, self.belief(i),
                                                                                      self.params))
        return SimEvent(i, "REPLAN", self.t, index=len(points), seconds=res.seconds)

    def replan(self) -> list[SimEvent]:
        """Check the due robots and replan the blocked ones now, in this thread; their ``REPLAN`` events."""
        from .replan import solve

        events = []
        for req in self.replan_requests():
            ev = self.apply_replan(req, solve(req))
            if ev is not None:
                events.append(ev)
        return events

    def _ctrl(self) -> tuple:
        return (self.state, self.aligning, self.wp, self.k, self.timeout, self.cmd, self.anchor, self.anchor_k,
                self.points, self.offset, self.count, self.cid, self.cpar, self.cmem, self.want)

    def _plugin_moving(self) -> bool:
        """Whether a robot with a Python (plug-in) controller follows a path: then every step goes through
        Python (:meth:`_python_step`), for the whole fleet."""
        return any(self.state[i] == State.MOVING for i in self._plugins)

    def _plugin_commands(self, belief: np.ndarray) -> None:
        """Each moving plug-in robot's commands for this step into ``want``."""
        for i, sel in self._plugins.items():
            if self.state[i] == State.MOVING and self.count[i] > 0:
                path = self.points[self.offset[i]:self.offset[i] + self.count[i]]
                v, w = sel.spec.plugin.command(belief[i].copy(), path, (int(self.cmem[i, 0]), float(self.cmem[i, 1])),
                                               dict(sel.params), self.dt)
                self.want[i] = float(v), float(w)

    def _python_step(self) -> np.ndarray:
        """One step through the backend's Python methods; returns its event rows (see stepper)."""
        moving = self.state == State.MOVING
        belief, logged, logged_pose = self.backend.sense(self.k, moving)
        if self.log_poses and logged.any():
            idx = np.flatnonzero(logged)
            self.poses.add(np.full(len(idx), self.t), idx, np.array(logged_pose[idx], dtype=float))
        flags, old = self._scratch[0], self._scratch[1]
        belief = np.ascontiguousarray(belief, dtype=float)
        self._plugin_commands(belief)
        control_fleet(belief, moving, self._ctrl(), self.gains, flags, old, self.world.arrays, self.world.radius)
        self.backend.actuate(self.cmd)
        if self._field:
            drive_movers(self.k, self.world.arrays, self.world.tables, self.world.movers.arrays, np.zeros(3),
                         self.backend.fg, self.mover_gains, False)
        still = moving & (flags & ENDED == 0)
        collided = self.world.collisions(self.backend.pose, still | self.backend.in_motion(), self.step_count, self.k,
                                         self.dt)
        if collided.any():
            self.backend.halt(collided)
        n_ev = settle_fleet(self.step_count, collided, flags, old, self._ctrl(), self._events, 0)
        return self._events[:n_ev]

    def _records_to_events(self, records: np.ndarray) -> list[SimEvent]:
        """Event records of rows ``(step, robot, old wp, new wp, flags)``, in order per robot."""
        out: list[SimEvent] = []
        for step, i, old, new, f in records.tolist():
            t0 = step * self.dt
            if f & STARTED:
                out.append(SimEvent(i, "START", t0))
            for w in range(old, new):
                out.append(SimEvent(i, "WP", t0, index=w))
            if f & ARRIVED:
                out.append(SimEvent(i, "WP", t0, index=new))
            if f & DONE:
                out.append(SimEvent(i, "DONE", t0))
            elif f & (STALLED | TIMED_OUT):
                why = "STALLED" if f & STALLED else "WATCHDOG" if self.cid[i] == DIRECT else "TIMEOUT"
                out.append(SimEvent(i, "FAIL", t0, reason=why))
            elif f & COLLIDED:  # a robot collides once per path: what[i] is this collision's
                what = int(self.world.what[i])
                out.append(SimEvent(i, "FAIL", (step + 1) * self.dt, index=what if what >= 0 else None,
                                    reason="COLLISION"))
        return out


_warm = False


def kernels_ready() -> bool:
    """True once :func:`warm_up` ran in this process."""
    return _warm


def warm_up() -> None:
    """Compile (first run) or load (from numba's cache) every kernel a host uses.

    Takes seconds once after installing or changing the code, then well under
    one; hosts call it in a worker thread before they accept clients, so the
    event loop never waits for the compiler.
    """
    global _warm
    if _warm:
        return
    from contract.frames import field_layout
    from contract.params import robot_params

    from . import replan  # noqa: F401 - the planners it uses load here, not on the loop when a robot first replans
    from .backends import make_backend

    p = robot_params()
    for name in ("ideal", "field"):
        sizes, world_of, origin, area = field_layout(2, "shared")
        core = SimCore(p, make_backend(name, 2, p), World(sizes, world_of, origin, area, p.collision_radius_m))
        core.world.set_blocks(0, np.array([[1.0, 1.0, 0.1, 0.1, 0.0]]))
        core.world.set_moving(0, [(np.array([0.04, 0.1, 2.0, 0.0]), np.array([[1.2, 0.3], [1.4, 0.3]]))])
        core.world.place_conflict(1, (0.5, 0.5, 0.0), core.backend.pose)
        for i in range(2):
            core.place(i, (0.3, 0.3, 0.0))
            core.set_path(i, np.array([[0.3, 0.3, 0.0], [0.5, 0.3, 0.0]]), i + 1)
        core.step()
        core.advance(5)
    _warm = True
