"""Collision geometry of one robot against walls, blocks, other robots and moving obstacles (compiled).

Kernels for :class:`robot_agent.engine.world.World` and the fused simulation loop
(:mod:`robot_agent.engine.stepper`).  Positions are world coordinates (m).  Blocks
are stored per world, packed at the front of ``(W, Bmax, 2)`` tables of
centres, half sizes and (cos, sin) of their angles; ``nblocks`` ``(W,)``
says how many each world has.

Moving obstacles belong to one robot each (their time is that robot's time
since its path began, :mod:`planners.moving`): robot ``i``'s are rows
``mo_first[i]`` to ``mo_first[i + 1]`` of ``mo_par`` ``(M, 4)`` (radius m,
speed m/s, repeat code, delay s), ``mo_pts`` ``(M, K, 2)`` their tracks
(world frame, a ``loop`` closed) with ``mo_cum`` ``(M, K)`` the arc length
at each point and ``mo_n`` ``(M,)`` the points used; rows ``mo_first[N]`` to
``mo_first[N + 1]`` are shared by every robot of world 0 (a fleet's).  On the
field an obstacle is an emulated robot (``mv_on``, :mod:`robot_agent.engine.movers`)
standing at ``mv_pose`` in its owner's frame instead of on its exact track;
``mv_halt`` records the step it was hit in, after which it stands.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import kernel

__all__ = ["block_distance", "collide", "obstacle_contact", "obstacle_position", "obstacle_xy", "robot_contacts",
           "wall_distance"]

ONCE, LOOP, PINGPONG = 0, 1, 2  #: repeat codes (planners.moving.REPEAT_MODES)


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
def obstacle_position(m: int, t: float, mo_par: np.ndarray, mo_pts: np.ndarray, mo_cum: np.ndarray,
                      mo_n: np.ndarray) -> tuple[float, float]:
    """Centre (m, world frame) of moving obstacle ``m`` at its time ``t`` (s since the path start)."""
    n = mo_n[m]
    length = mo_cum[m, n - 1]
    d = mo_par[m, 1] * max(t - mo_par[m, 3], 0.0)
    mode = int(mo_par[m, 2])
    if length <= 0.0:
        d = 0.0
    elif mode == LOOP:
        d = d % length
    elif mode == PINGPONG:
        d = d % (2.0 * length)
        if d > length:
            d = 2.0 * length - d
    else:
        d = min(d, length)
    j = 0
    while j < n - 2 and mo_cum[m, j + 1] < d:
        j += 1
    if n < 2:
        return mo_pts[m, 0, 0], mo_pts[m, 0, 1]
    seg = mo_cum[m, j + 1] - mo_cum[m, j]
    f = (d - mo_cum[m, j]) / seg if seg > 0.0 else 0.0
    return (mo_pts[m, j, 0] + f * (mo_pts[m, j + 1, 0] - mo_pts[m, j, 0]),
            mo_pts[m, j, 1] + f * (mo_pts[m, j + 1, 1] - mo_pts[m, j, 1]))


@kernel
def obstacle_xy(m: int, t: float, mo_par: np.ndarray, mo_pts: np.ndarray, mo_cum: np.ndarray, mo_n: np.ndarray,
                mv_on: np.ndarray, mv_pose: np.ndarray, gx: float, gy: float) -> tuple[float, float]:
    """Centre (m, world frame) of moving obstacle ``m`` at obstacle time ``t`` (s): on its track, or where the
    obstacle robot stands (its owner's frame has origin ``(gx, gy)``)."""
    if mv_on[m]:
        return mv_pose[m, 0] + gx, mv_pose[m, 1] + gy
    return obstacle_position(m, t, mo_par, mo_pts, mo_cum, mo_n)


@kernel
def obstacle_contact(i: int, x: float, y: float, t: float, radius: float, mo_first: np.ndarray, mo_par: np.ndarray,
                     mo_pts: np.ndarray, mo_cum: np.ndarray, mo_n: np.ndarray, mv_on: np.ndarray,
                     mv_pose: np.ndarray, gx: float, gy: float) -> int:
    """Index (among owner ``i``'s) of the first moving obstacle closer than ``radius`` plus its own radius to
    ``(x, y)`` (world, m) at obstacle time ``t`` (s), or -1; ``(gx, gy)`` the owner's frame origin."""
    for m in range(mo_first[i], mo_first[i + 1]):
        ox, oy = obstacle_xy(m, t, mo_par, mo_pts, mo_cum, mo_n, mv_on, mv_pose, gx, gy)
        if math.hypot(x - ox, y - oy) < radius + mo_par[m, 0]:
            return m - mo_first[i]
    return -1


@kernel
def collide(pose: np.ndarray, check: np.ndarray, step: int, k: np.ndarray, hit: np.ndarray, world: tuple,
            radius: float, step_travel: float, dt: float) -> None:
    """``hit[i]`` for robots in ``check`` that touch a wall, a block, another robot of their world or one of
    their moving obstacles; ``what[i]`` (in ``world``) says which obstacle (-1: none of those).

    ``pose`` ``(N, 3)`` is in each robot's frame, after the step; robot
    ``i``'s obstacles stand where they are ``k[i] + 1`` steps of ``dt`` (s)
    after its path began.  Broad phase: a robot at distance d from every
    wall and block cannot touch one for ``(d - radius) / step_travel``
    steps, so it is checked again only after that (``safe_until``, in
    simulation steps); moving obstacles are checked every step.
    """
    (origin, world_of, sizes, centre, half, cs, nblocks, shared, safe_until, mo_first, mo_par, mo_pts, mo_cum,
     mo_n, what, mv_on, mv_pose, mv_halt, mv_clock) = world
    n = len(pose)
    hit[:] = False
    robot_contacts(pose, origin, world_of, shared, radius, hit)
    for i in range(n):
        if not check[i]:
            hit[i] = False
            continue
        if hit[i]:
            what[i] = -1
        x, y = pose[i, 0] + origin[i, 0], pose[i, 1] + origin[i, 1]
        if mo_first[i + 1] > mo_first[i] and not hit[i]:
            m = obstacle_contact(i, x, y, (k[i] + 1) * dt, radius, mo_first, mo_par, mo_pts, mo_cum, mo_n, mv_on,
                                 mv_pose, origin[i, 0], origin[i, 1])
            if m >= 0:
                hit[i] = True
                what[i] = m
                if mv_on[mo_first[i] + m] and mv_halt[mo_first[i] + m] < 0:
                    mv_halt[mo_first[i] + m] = k[i]  # the obstacle robot stops where it was hit
                continue
        if mo_first[n + 1] > mo_first[n] and not hit[i] and world_of[i] == 0:
            m = obstacle_contact(n, x, y, 0.0, radius, mo_first, mo_par, mo_pts, mo_cum, mo_n, mv_on, mv_pose,
                                 0.0, 0.0)
            if m >= 0:
                hit[i] = True
                what[i] = m
                if mv_halt[mo_first[n] + m] < 0:
                    mv_halt[mo_first[n] + m] = mv_clock[mo_first[n] + m] - 1
                continue
        if safe_until[i] > step:
            continue
        w = world_of[i]
        d = min(wall_distance(x, y, sizes[w, 0], sizes[w, 1]), block_distance(x, y, w, centre, half, cs, nblocks))
        if d < radius:
            if not hit[i]:
                what[i] = -1
            hit[i] = True
        if step_travel > 0:
            safe_until[i] = step + int(math.floor((d - radius) / step_travel))
