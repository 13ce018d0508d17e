"""Worlds the robots of one host live in: frames, blocks and collisions (vectorised).

A host's robots share one world (the 3.6 m x 3.6 m field, each robot on its
sub-field) or each has a world of its own (the simulation pool).  Every robot
has an *origin* (x0, y0) in its world and a working *area* (w, h): protocol
coordinates are relative to the origin, and path points and placements must
lie in ``[0, w] x [0, h]``.

Blocks built by a robot (``T,T,B``, in its frame) are stored in world
coordinates, tagged with their builder; they are obstacles for every robot of
that world.  The world's boundary is a wall.  A robot collides when a block,
a wall or another robot of its world comes closer than the collision radius
to its centre (robots: twice that radius between centres).
"""

from __future__ import annotations

import numpy as np

__all__ = ["FIELD_SIZE", "SUBFIELD_ORIGINS", "SUBFIELD_SIZE", "World", "field_layout"]

FIELD_SIZE = (3.6, 3.6)
SUBFIELD_SIZE = (1.8, 1.8)
#: origins of sub-fields 1..4: lower-left, lower-right, upper-left, upper-right
SUBFIELD_ORIGINS = ((0.0, 0.0), (1.8, 0.0), (0.0, 1.8), (1.8, 1.8))

_DENSE_PAIRS = 512  # up to this many robots in multi-robot worlds, pairs are checked densely


class World:
    """Frames, blocks and collision checks for ``n`` robots.

    ``world_of`` ``(N,)`` gives each robot's world index, ``sizes`` ``(W, 2)``
    the worlds' sizes (m), ``origin`` and ``area`` ``(N, 2)`` each robot's
    frame and working area (m).
    """

    def __init__(self, sizes: np.ndarray, world_of: np.ndarray, origin: np.ndarray, area: np.ndarray,
                 collision_radius: float) -> None:
        self.sizes = np.asarray(sizes, dtype=float).reshape(-1, 2)
        self.world_of = np.asarray(world_of, dtype=np.int64)
        self.origin = np.asarray(origin, dtype=float).reshape(-1, 2).copy()
        self.area = np.asarray(area, dtype=float).reshape(-1, 2).copy()
        self.radius = float(collision_radius)
        self.n = len(self.world_of)
        self._blocks: dict[int, np.ndarray] = {}  # owner -> (B, 5) world frame
        self._shift = np.stack([self.world_of * 1000.0, np.zeros(self.n)], axis=1)
        counts = np.bincount(self.world_of, minlength=len(self.sizes))
        self._shared = np.flatnonzero(counts[self.world_of] > 1)  # robots that can meet robots
        #: upper bound of how far a robot travels in one step (m); set by the simulation core
        self.step_travel = 0.0
        # Broad phase: a robot at distance d from every block and wall cannot touch one
        # for (d - radius) / step_travel steps; it is only checked again after that.
        self._safe_until = np.zeros(self.n, dtype=np.int64)
        self._rebuild()

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

    def _rebuild(self) -> None:
        """Per-robot padded block arrays ``(N, Bmax)`` of the robot's world's blocks."""
        per_world: list[list[np.ndarray]] = [[] for _ in range(len(self.sizes))]
        for owner, b in sorted(self._blocks.items()):
            per_world[self.world_of[owner]].append(b)
        stacked = [np.concatenate(bs) if bs else np.zeros((0, 5)) for bs in per_world]
        bmax = max((len(b) for b in stacked), default=0)
        table = np.zeros((len(stacked), max(bmax, 1), 5))
        valid = np.zeros((len(stacked), max(bmax, 1)), dtype=bool)
        for w, b in enumerate(stacked):
            table[w, : len(b)] = b
            valid[w, : len(b)] = True
        rows = table[self.world_of]  # (N, Bmax, 5)
        self._bc = rows[..., :2]
        self._bhalf = rows[..., 2:4] / 2
        self._bcos, self._bsin = np.cos(rows[..., 4]), np.sin(rows[..., 4])
        self._bvalid = valid[self.world_of]
        self._has_blocks = bool(bmax)
        self.invalidate()

    def invalidate(self, i: int | None = None) -> None:
        """Forget the broad-phase horizon of robot ``i`` (all robots if None): check it next step."""
        if i is None:
            self._safe_until = np.zeros(self.n, dtype=np.int64)
        else:
            self._safe_until[i] = 0

    # ------------------------------------------------------------------ geometry

    def to_world(self, pose_local: np.ndarray) -> np.ndarray:
        """World ``(N, 2)`` positions of local poses ``(N, 2+)``."""
        return pose_local[:, :2] + self.origin

    def block_distance(self, xy_world: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Signed distance (m) from robots ``idx``'s world positions ``(len(idx), 2)`` to the
        nearest block of their world (negative inside; ``inf`` without blocks)."""
        if not self._has_blocks:
            return np.full(len(idx), np.inf)
        d = xy_world[:, None, :] - self._bc[idx]
        c, s = self._bcos[idx], self._bsin[idx]
        lx = np.abs(c * d[..., 0] + s * d[..., 1]) - self._bhalf[idx, :, 0]
        ly = np.abs(c * d[..., 1] - s * d[..., 0]) - self._bhalf[idx, :, 1]
        sd = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0)) + np.minimum(np.maximum(lx, ly), 0.0)
        return np.where(self._bvalid[idx], sd, np.inf).min(axis=1)

    def wall_distance(self, xy_world: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Distance (m) from robots ``idx``'s world positions to their world's boundary."""
        size = self.sizes[self.world_of[idx]]
        return np.minimum(np.minimum(xy_world[:, 0], size[:, 0] - xy_world[:, 0]),
                          np.minimum(xy_world[:, 1], size[:, 1] - xy_world[:, 1]))

    def robot_contacts(self, xy_world_all: np.ndarray) -> np.ndarray:
        """Mask ``(N,)`` of robots closer than two collision radii to another robot of their world."""
        hit = np.zeros(self.n, dtype=bool)
        idx = self._shared
        if len(idx) < 2:
            return hit
        p = xy_world_all[idx] + self._shift[idx]
        if len(idx) <= _DENSE_PAIRS:
            d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
            np.fill_diagonal(d, np.inf)
            hit[idx] = (d < 2 * self.radius).any(axis=1)
        else:
            from scipy.spatial import cKDTree

            pairs = cKDTree(p).query_pairs(2 * self.radius, output_type="ndarray")
            hit[idx[pairs.ravel()]] = True
        return hit

    def collisions(self, pose_local: np.ndarray, check: np.ndarray, step: int = 0) -> np.ndarray:
        """Mask ``(N,)`` of robots in ``check`` that touch a block, a wall or another robot.

        ``step`` is the simulation step count, for the broad phase (robots far
        from every obstacle are not checked again until they could reach one).
        """
        out = np.zeros(self.n, dtype=bool)
        if len(self._shared):
            out |= self.robot_contacts(self.to_world(pose_local)) & check
        due = check & (self._safe_until <= step)
        if not due.any():
            return out
        idx = np.flatnonzero(due)
        sub = pose_local[idx, :2] + self.origin[idx]
        d = np.minimum(self.wall_distance(sub, idx), self.block_distance(sub, idx))
        out[idx] |= d < self.radius
        if self.step_travel > 0:
            self._safe_until[idx] = step + np.floor((d - self.radius) / self.step_travel).astype(np.int64)
        return out

    def place_conflict(self, i: int, pose_local: tuple[float, float, float], poses_local: np.ndarray) -> str | None:
        """Why robot ``i`` cannot be put at ``pose_local`` (a wall, a block or a robot is within the
        collision radius), or None."""
        xy = np.asarray(pose_local[:2], dtype=float)[None, :] + self.origin[i]
        idx = np.array([i])
        if self.wall_distance(xy, idx)[0] < self.radius:
            return "the robot would touch the field's wall there"
        if self.block_distance(xy, idx)[0] < self.radius:
            return "the robot would touch a block there"
        same = np.flatnonzero((self.world_of == self.world_of[i]) & (np.arange(self.n) != i))
        if len(same):
            others = self.to_world(poses_local)[same]
            if (np.hypot(*(others - xy).T) < 2 * self.radius).any():
                return "another robot stands there"
        return None


def field_layout(
    n: int,
    mode: str = "auto",
    area: tuple[float, float] | list[tuple[float, float]] | None = None,
    origins: list[tuple[float, float]] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where ``n`` robots live: ``(sizes (W, 2), world_of (N,), origin (N, 2), area (N, 2))``, metres.

    ``area`` is one (w, h) for every robot or one per robot (default: a
    1.8 m sub-field).  ``mode`` ``shared``: one 3.6 m field; robot i defaults
    to sub-field i (origins (0,0), (1.8,0), (0,1.8), (1.8,1.8)), or to origin
    (0, 0) when its area is larger than a sub-field (e.g. the whole field).
    ``separate``: every robot has a world of its own, of its area's size,
    origin (0, 0).  ``auto``: shared for up to 4 robots, separate beyond.
    """
    if n < 1:
        raise ValueError("`robots` must be >= 1")
    if mode == "auto":
        mode = "shared" if n <= 4 else "separate"
    if mode not in ("shared", "separate"):
        raise ValueError(f"`world` must be auto, shared or separate, got {mode!r}")
    a = np.array(area if area is not None else SUBFIELD_SIZE, dtype=float)
    if a.shape == (2,):
        a = np.tile(a, (n, 1))
    if a.shape != (n, 2) or not np.isfinite(a).all() or (a <= 0).any():
        raise ValueError(f"`area` must be W,H > 0 (metres), once or once per robot ({n}), got {area!r}")
    if mode == "separate":
        if origins is not None:
            raise ValueError("`origins` only apply to a shared world")
        return a.copy(), np.arange(n), np.zeros((n, 2)), a
    big = (a > np.array(SUBFIELD_SIZE) + 1e-9).any(axis=1)
    if origins is not None:
        o = np.array(origins, dtype=float).reshape(-1, 2)
        if len(o) != n:
            raise ValueError(f"`origins` must give one X,Y per robot ({n}), got {len(o)}")
    elif n <= 4 or big.all():
        o = np.array([(0.0, 0.0) if big[i] else SUBFIELD_ORIGINS[i % 4] for i in range(n)], dtype=float)
    else:
        raise ValueError(f"a shared field has 4 sub-fields, not {n}: use world='separate' or give origins")
    size = np.array(FIELD_SIZE)
    if (o < 0).any() or ((o + a) > size + 1e-9).any():
        raise ValueError(f"robot areas must lie inside the {size[0]} m x {size[1]} m field")
    return size[None, :], np.zeros(n, dtype=np.int64), o, a
