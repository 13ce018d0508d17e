"""Worlds the robots of one host live in: frames, blocks and collisions.

A host's robots share one world (the 3.6 m x 3.6 m field, each robot on its
sub-field) or each has a world of its own (the simulation pool); see
:func:`contract.frames.field_layout`.  Every robot has an *origin* (x0,
y0) in its world and a working *area* (w, h): protocol coordinates are
relative to the origin, and path points and placements must lie in
``[0, w] x [0, h]``.

Blocks built by a robot (``T,T,B``, in its frame) are stored in world
coordinates, tagged with their builder; they are obstacles for every robot of
that world.  The world's boundary is a wall.  A robot collides when a block,
a wall or another robot of its world comes closer than the collision radius
to its centre (robots: twice that radius between centres).  The geometry is
compiled (:mod:`robot_agent.engine.contact`).

Moving obstacles (``T,T,M``, :mod:`planners.moving`) belong to the robot
that was sent them: their time is that robot's time since its path began,
so they collide with that robot only.  In a simulation they move exactly as
the environment says.  On the emulated field (:meth:`World.drive`) each is
an emulated robot the testbed drives along its track
(:mod:`robot_agent.engine.movers`): it starts again from its first waypoint with
every path of its robot, touches that robot as a robot does (two collision
radii between centres) and stops where it was hit.  A fleet's obstacles
are shared by all its robots (:meth:`World.set_shared_moving`), on the
fleet's clock.
"""

from __future__ import annotations

import numpy as np

from contract.params import RobotParams

from .backends import FieldBackend
from .contact import block_distance, collide, obstacle_contact, wall_distance
from .movers import mover_key, reset_mover, track_tables

__all__ = ["World"]

_NO_POSE = np.zeros((1, 3))  # the obstacle robots' poses in compiled code when obstacles are exact


class World:
    """Frames, blocks and collision checks for ``n`` robots.

    ``world_of`` ``(N,)`` gives each robot's world index, ``sizes`` ``(W, 2)``
    the worlds' sizes (m), ``origin`` and ``area`` ``(N, 2)`` each robot's
    frame and working area (m).
    """

    def __init__(self, sizes: np.ndarray, world_of: np.ndarray, origin: np.ndarray, area: np.ndarray,
                 collision_radius: float) -> None:
        self.sizes = np.ascontiguousarray(np.asarray(sizes, dtype=float).reshape(-1, 2))
        self.world_of = np.ascontiguousarray(world_of, dtype=np.int64)
        self.origin = np.asarray(origin, dtype=float).reshape(-1, 2).copy()
        self.area = np.asarray(area, dtype=float).reshape(-1, 2).copy()
        self.radius = float(collision_radius)
        self.n = len(self.world_of)
        self._blocks: dict[int, np.ndarray] = {}  # owner -> (B, 5) world frame
        counts = np.bincount(self.world_of, minlength=len(self.sizes))
        self.shared = np.flatnonzero(counts[self.world_of] > 1)  #: robots that can meet robots
        self._alone = counts[self.world_of] == 1
        #: upper bound of how far a robot travels in one step (m); set by the simulation core
        self.step_travel = 0.0
        #: broad phase: the step until which each robot cannot touch a wall or block
        self.safe_until = np.zeros(self.n, dtype=np.int64)
        self._hit = np.zeros(self.n, dtype=bool)
        # owner (a robot, or n: shared by the fleet) -> [(params (4,), pts (K, 2) its frame)]
        self._moving: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        #: per robot, the moving obstacle (its index among the robot's) of its last collision, -1 for others
        self.what = np.full(self.n, -1, dtype=np.int64)
        self.driven: RobotParams | None = None  #: the obstacle robots' parameters on the field (None: exact)
        self._rebuild()
        self._rebuild_moving()

    # ------------------------------------------------------------------ blocks

    def set_blocks(self, owner: int, blocks_local: np.ndarray) -> int:
        """Replace the blocks robot ``owner`` built with ``blocks_local`` ``(B, 5)`` (its frame:
        cx, cy, w, h in m, angle in rad); returns how many blocks it removed."""
        old = self._blocks.pop(owner, np.zeros((0, 5)))
        b = np.asarray(blocks_local, dtype=float).reshape(-1, 5).copy()
        if len(b):
            b[:, :2] += self.origin[owner]
            self._blocks[owner] = b
        self._rebuild()
        return len(old)

    def load_blocks(self, owner: int, blocks_local: np.ndarray) -> None:
        """:meth:`set_blocks` for a robot alone in its world (a separate layout): the world's rows of the block
        tables are rewritten in place when the blocks fit them (no rebuild of every world's tables: what a
        training environment does at each episode of each of many robots)."""
        w = int(self.world_of[owner])
        b = np.asarray(blocks_local, dtype=float).reshape(-1, 5)
        if not self._alone[owner] or len(b) > self.centre.shape[1]:
            self.set_blocks(owner, b)
            return
        b = b.copy()
        b[:, :2] += self.origin[owner]
        if len(b):
            self._blocks[owner] = b
        else:
            self._blocks.pop(owner, None)
        nb = len(b)
        self.centre[w] = 0.0
        self.half[w] = 0.0
        self.cs[w] = 0.0
        self.centre[w, :nb] = b[:, :2]
        self.half[w, :nb] = b[:, 2:4] / 2
        self.cs[w, :nb, 0], self.cs[w, :nb, 1] = np.cos(b[:, 4]), np.sin(b[:, 4])
        self.nblocks[w] = nb
        self.invalidate(owner)

    def blocks_local(self, owner: int) -> np.ndarray:
        """The blocks robot ``owner`` built, ``(B, 5)`` in its frame."""
        b = self._blocks.get(owner, np.zeros((0, 5))).copy()
        b[:, :2] -= self.origin[owner]
        return b

    def world_blocks_local(self, i: int) -> np.ndarray:
        """Every block of robot ``i``'s world (whoever built it), ``(B, 5)`` in its frame: its static map."""
        w = self.world_of[i]
        mine = [b for owner, b in sorted(self._blocks.items()) if self.world_of[owner] == w]
        out = np.concatenate(mine) if mine else np.zeros((0, 5))
        out[:, :2] -= self.origin[i]
        return out

    def _rebuild(self) -> None:
        """Per-world block tables ``(W, Bmax, 2)``, blocks packed at the front."""
        per_world: list[list[np.ndarray]] = [[] for _ in range(len(self.sizes))]
        for owner, b in sorted(self._blocks.items()):
            per_world[self.world_of[owner]].append(b)
        stacked = [np.concatenate(bs) if bs else np.zeros((0, 5)) for bs in per_world]
        self.nblocks = np.array([len(b) for b in stacked], dtype=np.int64)
        table = np.zeros((len(stacked), max(int(self.nblocks.max(initial=0)), 1), 5))
        for w, b in enumerate(stacked):
            table[w, : len(b)] = b
        self.centre = np.ascontiguousarray(table[..., :2])
        self.half = np.ascontiguousarray(table[..., 2:4] / 2)
        self.cs = np.ascontiguousarray(np.stack([np.cos(table[..., 4]), np.sin(table[..., 4])], axis=-1))
        self.invalidate()

    def invalidate(self, i: int | None = None) -> None:
        """Forget the broad-phase horizon of robot ``i`` (all robots if None): check it next step."""
        if i is None:
            self.safe_until[:] = 0
        else:
            self.safe_until[i] = 0

    # ------------------------------------------------------------------ moving obstacles

    def set_moving(self, owner: int, obstacles: list[tuple[np.ndarray, np.ndarray]]) -> int:
        """Replace robot ``owner``'s moving obstacles with ``obstacles``: per obstacle its parameters
        (radius m, speed m/s, repeat code, delay s) and waypoints ``(K, 2)`` in its frame (m); returns how
        many it had."""
        old = len(self._moving.pop(owner, []))
        if obstacles:
            self._moving[owner] = [(np.asarray(par, dtype=float).reshape(4).copy(),
                                    np.asarray(pts, dtype=float).reshape(-1, 2).copy()) for par, pts in obstacles]
        self._rebuild_moving(owner)
        return old

    def moving_local(self, owner: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """Robot ``owner``'s moving obstacles as :meth:`set_moving` took them (params, waypoints in its frame)."""
        return [(par.copy(), pts.copy()) for par, pts in self._moving.get(owner, [])]

    def drive(self, params: RobotParams) -> None:
        """From now on moving obstacles are emulated field robots of ``params`` (:mod:`robot_agent.engine.movers`)."""
        self.driven = params
        self._rebuild_moving()

    def set_shared_moving(self, obstacles: list[tuple[np.ndarray, np.ndarray]], key: int) -> None:
        """Obstacle robots every robot of world 0 meets (a fleet's, on its clock from now; noise ``key``); as
        :meth:`set_moving` takes them, in world 0's frame.  Only on the field (:meth:`drive`)."""
        if self.driven is None:
            raise ValueError("shared moving obstacles are driven obstacle robots: call drive() first")
        self._moving.pop(self.n, None)
        if obstacles:
            self._moving[self.n] = [(np.asarray(par, dtype=float).reshape(4).copy(),
                                     np.asarray(pts, dtype=float).reshape(-1, 2).copy()) for par, pts in obstacles]
        self._rebuild_moving(self.n)
        self.restart_movers(self.n, key)

    def restart_movers(self, owner: int, key: int) -> None:
        """Owner ``owner``'s obstacle robots stand at their first waypoints, their runs begun with noise from
        ``key`` (a path of the robot begins); nothing when obstacles are exact."""
        if self.driven is None:
            return
        fg = self.movers.fg
        for j, m in enumerate(range(self.mo_first[owner], self.mo_first[owner + 1])):
            reset_mover(m, np.uint64(mover_key(key, j)), self.mo_par, self.mv_pts, self.mo_n, self.movers.arrays, fg)
            self.mv_halt[m] = -1
            self.mv_clock[m] = 0

    def halted(self, owner: int) -> np.ndarray:
        """The step (since their track began) each of owner ``owner``'s obstacle robots was hit in (-1: not)."""
        return self.mv_halt[self.mo_first[owner]:self.mo_first[owner + 1]].copy()

    def moving_count(self, owner: int) -> int:
        """How many moving obstacles robot ``owner`` has."""
        return len(self._moving.get(owner, []))

    def _rebuild_moving(self, changed: int = -1) -> None:
        """Tables of every robot's obstacle tracks, robot by robot, then the shared ones (see
        :mod:`robot_agent.engine.contact`): in the world's frame for exact discs, in the owner's for obstacle robots;
        the obstacle robots of owners other than ``changed`` keep their state."""
        world: list[tuple[np.ndarray, np.ndarray]] = []
        local: list[tuple[np.ndarray, np.ndarray]] = []
        first = np.zeros(self.n + 2, dtype=np.int64)
        for i in range(self.n + 1):
            at = self.origin[i] if i < self.n else np.zeros(2)
            for par, pts in self._moving.get(i, []):
                world.append((par, pts + at))
                local.append((par, pts))
            first[i + 1] = len(world)
        self.mo_first = first
        self.mo_par, self.mo_pts, self.mo_cum, self.mo_n = track_tables(world)
        m = len(self.mo_par)
        kept = getattr(self, "movers", None), getattr(self, "mv_halt", None), getattr(self, "mv_clock", None)
        old_first = getattr(self, "_mv_first", None)
        self.mv_on = np.zeros(m, dtype=bool)
        self.mv_halt = np.full(m, -1, dtype=np.int64)
        self.mv_clock = np.zeros(m, dtype=np.int64)
        self._mv_first = first
        if self.driven is None:
            self.movers = None
            self.mv_pts, self.mv_cum = self.mo_pts, self.mo_cum
            return
        _, self.mv_pts, self.mv_cum, _ = track_tables(local)
        self.movers = FieldBackend(m, self.driven)
        self.mv_on[: len(world)] = True
        self.mo_par[: len(world), 0] = self.radius  # a robot: it touches robots at two collision radii
        for owner in range(self.n + 1):
            a, b = first[owner], first[owner + 1]
            if owner != changed and kept[0] is not None and old_first is not None \
                    and old_first[owner + 1] - old_first[owner] == b - a:
                old = slice(old_first[owner], old_first[owner + 1])  # an obstacle robot under way drives on
                for new_arr, old_arr in zip(self.movers.arrays, kept[0].arrays):
                    new_arr[a:b] = old_arr[old]
                self.mv_halt[a:b], self.mv_clock[a:b] = kept[1][old], kept[2][old]
            else:
                self.restart_movers(owner, 0)

    # ------------------------------------------------------------------ geometry

    @property
    def arrays(self) -> tuple:
        """``(origin, world_of, sizes, centre, half, cs, nblocks, shared, safe_until, mo_first, mo_par, mo_pts,
        mo_cum, mo_n, what, mv_on, mv_pose, mv_halt, mv_clock)`` for :func:`robot_agent.engine.contact.collide`, the
        arrays themselves; ``mv_*`` the obstacle robots' (:mod:`robot_agent.engine.movers`): driven or not, poses in
        their owner's frame, the step each was hit in (-1: not), the shared ones' clocks."""
        pose = self.movers.pose if self.movers is not None else _NO_POSE
        return (self.origin, self.world_of, self.sizes, self.centre, self.half, self.cs, self.nblocks,
                self.shared, self.safe_until, self.mo_first, self.mo_par, self.mo_pts, self.mo_cum, self.mo_n,
                self.what, self.mv_on, pose, self.mv_halt, self.mv_clock)

    @property
    def tables(self) -> tuple[np.ndarray, np.ndarray]:
        """The obstacle robots' tracks in their owners' frames, ``(pts (M, K, 2), cum (M, K))``."""
        return self.mv_pts, self.mv_cum

    def to_world(self, pose_local: np.ndarray) -> np.ndarray:
        """World ``(N, 2)`` positions of local poses ``(N, 2+)``."""
        return pose_local[:, :2] + self.origin

    def collisions(self, pose_local: np.ndarray, check: np.ndarray, step: int = 0, k: np.ndarray | None = None,
                   dt: float = 0.0) -> np.ndarray:
        """Mask ``(N,)`` of robots in ``check`` that touch a block, a wall, another robot or a moving obstacle
        (which one: :attr:`what`).

        ``step`` is the simulation step count, for the broad phase (robots far
        from every obstacle are not checked again until they could reach one);
        ``k`` ``(N,)`` the steps of ``dt`` (s) since each robot's path began
        before this one (its obstacles' time is ``(k + 1) dt``).
        """
        kk = np.zeros(self.n, dtype=np.int64) if k is None else np.ascontiguousarray(k, dtype=np.int64)
        collide(np.ascontiguousarray(pose_local, dtype=float), np.asarray(check, dtype=bool), int(step), kk,
                self._hit, self.arrays, self.radius, self.step_travel, float(dt))
        return self._hit.copy()

    def place_conflict(self, i: int, pose_local: tuple[float, float, float], poses_local: np.ndarray) -> str | None:
        """Why robot ``i`` cannot be put at ``pose_local`` (a wall, a block or a robot is within the
        collision radius), or None."""
        x, y = float(pose_local[0]) + self.origin[i, 0], float(pose_local[1]) + self.origin[i, 1]
        w = int(self.world_of[i])
        if wall_distance(x, y, self.sizes[w, 0], self.sizes[w, 1]) < self.radius:
            return "the robot would touch the field's wall there"
        if block_distance(x, y, w, self.centre, self.half, self.cs, self.nblocks) < self.radius:
            return "the robot would touch a block there"
        pose = self.movers.pose if self.movers is not None else _NO_POSE
        for g, (gx, gy) in ((i, self.origin[i]), (self.n, (0.0, 0.0))):
            m = obstacle_contact(g, x, y, 0.0, self.radius, self.mo_first, self.mo_par, self.mo_pts, self.mo_cum,
                                 self.mo_n, self.mv_on, pose, float(gx), float(gy))
            if m >= 0:
                return f"moving obstacle {m} stands there when the path starts"
        same = np.flatnonzero((self.world_of == w) & (np.arange(self.n) != i))
        if len(same):
            others = self.to_world(poses_local)[same]
            if (np.hypot(others[:, 0] - x, others[:, 1] - y) < 2 * self.radius).any():
                return "another robot stands there"
        return None
