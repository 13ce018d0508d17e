"""Collision geometry of one robot against walls, blocks and other robots (compiled).

Kernels for :class:`robot_agent.world.World` and the fused simulation loop
(:mod:`robot_agent.stepper`).  Positions are world coordinates (m).  Blocks
are stored per world, packed at the front of ``(W, Bmax, 2)`` tables of
centres, half sizes and (cos, sin) of their angles; ``nblocks`` ``(W,)``
says how many each world has.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import kernel

__all__ = ["block_distance", "collide", "robot_contacts", "wall_distance"]


@kernel
def block_distance(x: float, y: float, w: int, centre: np.ndarray, half: np.ndarray, cs: np.ndarray,
                   nblocks: np.ndarray) -> float:
    """Signed distance (m) from ``(x, y)`` to the nearest block of world ``w`` (negative inside;
    ``inf`` without blocks)."""
    best = math.inf
    for b in range(nblocks[w]):
        dx, dy = x - centre[w, b, 0], y - centre[w, b, 1]
        c, s = cs[w, b, 0], cs[w, b, 1]
        lx = abs(c * dx + s * dy) - half[w, b, 0]
        ly = abs(c * dy - s * dx) - half[w, b, 1]
        d = math.hypot(max(lx, 0.0), max(ly, 0.0)) + min(max(lx, ly), 0.0)
        best = min(best, d)
    return best


@kernel
def wall_distance(x: float, y: float, width: float, height: float) -> float:
    """Distance (m) from ``(x, y)`` to the boundary of a ``width`` x ``height`` world."""
    return min(min(x, width - x), min(y, height - y))


@kernel
def robot_contacts(pose: np.ndarray, origin: np.ndarray, world_of: np.ndarray, shared: np.ndarray,
                   radius: float, hit: np.ndarray) -> None:
    """Set ``hit[i]`` for robots of ``shared`` closer than two radii to another robot of their world.

    Sweep and prune along world x (worlds set 1000 m apart): O(S log S) plus contacts.
    """
    m = len(shared)
    if m < 2:
        return
    xs = np.empty(m)
    ys = np.empty(m)
    for j in range(m):
        i = shared[j]
        xs[j] = pose[i, 0] + origin[i, 0] + 1000.0 * world_of[i]
        ys[j] = pose[i, 1] + origin[i, 1]
    order = np.argsort(xs)
    reach = 2.0 * radius
    for a in range(m):
        ja = order[a]
        for b in range(a + 1, m):
            jb = order[b]
            if xs[jb] - xs[ja] >= reach:
                break
            if math.hypot(xs[jb] - xs[ja], ys[jb] - ys[ja]) < reach:
                hit[shared[ja]] = True
                hit[shared[jb]] = True


@kernel
def collide(pose: np.ndarray, check: np.ndarray, step: int, hit: np.ndarray, origin: np.ndarray,
            world_of: np.ndarray, sizes: np.ndarray, centre: np.ndarray, half: np.ndarray, cs: np.ndarray,
            nblocks: np.ndarray, shared: np.ndarray, safe_until: np.ndarray, radius: float,
            step_travel: float) -> None:
    """``hit[i]`` for robots in ``check`` that touch a wall, a block or another robot of their world.

    ``pose`` ``(N, 3)`` is in each robot's frame.  Broad phase: a robot at
    distance d from every wall and block cannot touch one for
    ``(d - radius) / step_travel`` steps, so it is checked again only after
    that (``safe_until``, in simulation steps).
    """
    n = len(pose)
    hit[:] = False
    robot_contacts(pose, origin, world_of, shared, radius, hit)
    for i in range(n):
        if not check[i]:
            hit[i] = False
            continue
        if safe_until[i] > step:
            continue
        x, y = pose[i, 0] + origin[i, 0], pose[i, 1] + origin[i, 1]
        w = world_of[i]
        d = min(wall_distance(x, y, sizes[w, 0], sizes[w, 1]), block_distance(x, y, w, centre, half, cs, nblocks))
        if d < radius:
            hit[i] = True
        if step_travel > 0:
            safe_until[i] = step + int(math.floor((d - radius) / step_travel))
