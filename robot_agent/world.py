"""Worlds the robots of one host live in: frames, blocks and collisions.

A host's robots share one world (the 3.6 m x 3.6 m field, each robot on its
sub-field) or each has a world of its own (the simulation pool); see
:func:`robot_agent.frames.field_layout`.  Every robot has an *origin* (x0,
y0) in its world and a working *area* (w, h): protocol coordinates are
relative to the origin, and path points and placements must lie in
``[0, w] x [0, h]``.

Blocks built by a robot (``T,T,B``, in its frame) are stored in world
coordinates, tagged with their builder; they are obstacles for every robot of
that world.  The world's boundary is a wall.  A robot collides when a block,
a wall or another robot of its world comes closer than the collision radius
to its centre (robots: twice that radius between centres).  The geometry is
compiled (:mod:`robot_agent.contact`).

Moving obstacles (``T,T,M``, :mod:`planners.moving`) belong to the robot
that was sent them: their time is that robot's time since its path began,
so they collide with that robot only.  In a simulation they move exactly as
the environment says; on the emulated field they stand for robots the
testbed drives along the same tracks (docs/protocol.md).
"""

from __future__ import annotations

import numpy as np

from .contact import LOOP, block_distance, collide, obstacle_contact, wall_distance

__all__ = ["World"]


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
        #: upper bound of how far a robot travels in one step (m); set by the simulation core
        self.step_travel = 0.0
        #: broad phase: the step until which each robot cannot touch a wall or block
        self.safe_until = np.zeros(self.n, dtype=np.int64)
        self._hit = np.zeros(self.n, dtype=bool)
        self._moving: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}  # owner -> [(params (4,), pts (K, 2))]
        #: per robot, the moving obstacle (its index among the robot's) of its last collision, -1 for others
        self.what = np.full(self.n, -1, dtype=np.int64)
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
                                    np.asarray(pts, dtype=float).reshape(-1, 2) + self.origin[owner])
                                   for par, pts in obstacles]
        self._rebuild_moving()
        return old

    def moving_local(self, owner: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """Robot ``owner``'s moving obstacles as :meth:`set_moving` took them (params, waypoints in its frame)."""
        return [(par.copy(), pts - self.origin[owner]) for par, pts in self._moving.get(owner, [])]

    def moving_count(self, owner: int) -> int:
        """How many moving obstacles robot ``owner`` has."""
        return len(self._moving.get(owner, []))

    def _rebuild_moving(self) -> None:
        """Tables of every robot's obstacle tracks, robot by robot (see :mod:`robot_agent.contact`)."""
        tracks: list[tuple[np.ndarray, np.ndarray]] = []
        first = np.zeros(self.n + 1, dtype=np.int64)
        for i in range(self.n):
            for par, pts in self._moving.get(i, []):
                if int(par[2]) == LOOP and len(pts) > 1:
                    pts = np.vstack([pts, pts[:1]])
                tracks.append((par, pts))
            first[i + 1] = len(tracks)
        k = max((len(p) for _, p in tracks), default=1)
        self.mo_first = first
        self.mo_par = np.zeros((max(len(tracks), 1), 4))
        self.mo_pts = np.zeros((len(self.mo_par), k, 2))
        self.mo_cum = np.zeros((len(self.mo_par), k))
        self.mo_n = np.ones(len(self.mo_par), dtype=np.int64)
        for m, (par, pts) in enumerate(tracks):
            self.mo_par[m] = par
            self.mo_pts[m, : len(pts)] = pts
            self.mo_cum[m, 1 : len(pts)] = np.cumsum(np.hypot(*np.diff(pts, axis=0).T))
            self.mo_n[m] = len(pts)

    # ------------------------------------------------------------------ geometry

    @property
    def arrays(self) -> tuple:
        """``(origin, world_of, sizes, centre, half, cs, nblocks, shared, safe_until, mo_first, mo_par, mo_pts,
        mo_cum, mo_n, what)`` for :func:`robot_agent.contact.collide`, the arrays themselves."""
        return (self.origin, self.world_of, self.sizes, self.centre, self.half, self.cs, self.nblocks,
                self.shared, self.safe_until, self.mo_first, self.mo_par, self.mo_pts, self.mo_cum, self.mo_n,
                self.what)

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
        m = obstacle_contact(i, x, y, 0.0, self.radius, self.mo_first, self.mo_par, self.mo_pts, self.mo_cum,
                             self.mo_n)
        if m >= 0:
            return f"moving obstacle {m} stands there when the path starts"
        same = np.flatnonzero((self.world_of == w) & (np.arange(self.n) != i))
        if len(same):
            others = self.to_world(poses_local)[same]
            if (np.hypot(others[:, 0] - x, others[:, 1] - y) < 2 * self.radius).any():
                return "another robot stands there"
        return None
