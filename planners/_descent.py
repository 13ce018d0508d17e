"""The compiled descent of :func:`planners.fast_marching.descend` (numba, imported lazily).

The arrival times are read from a flattened grid padded by two blocked cells
(``BIG``), so that the 4 x 4 stencil around any interpolation quad exists
without clamping: ``k = row * W + col``, ``W = nx + 4``.  The behaviour is
described in :func:`planners.fast_marching.descend`; every value read lies
within 3 cells (Chebyshev) of the cell of a position the descent visits
(column ``int(x * inv_h)``, row ``int(y * inv_h)``): what
:class:`~planners.fast_marching.FrontMarch` makes sure is final.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

BIG = 1e30  # arrival time standing for "blocked": finite, so bilinear weights of 0 stay 0
RIDGE_WATCH = 8  # steps checked for a ridge after the start, a fallback or a ridge step
RIDGE_DIVERGENCE = 0.3  # 1/cell; about the angle (rad) between the two ways round on a ridge
_ANGLES = np.linspace(0, 2 * math.pi, 32, endpoint=False)
CIRCLE_X = np.cos(_ANGLES)  # the circle of two cells searched on a ridge
CIRCLE_Y = np.sin(_ANGLES)

_jit = njit(cache=True, nogil=True)


@_jit
def _up(c, lo, hi):
    """Upwind difference at a cell of time ``c`` with neighbours ``lo`` (before) and ``hi`` (after)."""
    if c >= BIG:
        return 0.0
    if lo <= hi:
        return c - lo if c > lo else 0.0
    return hi - c if c > hi else 0.0


@_jit
def _t_at(t, W, inv_h, x, y):
    """Bilinear arrival time at (x, y) (m)."""
    u = x * inv_h + 1.5
    v = y * inv_h + 1.5
    j = int(u)
    i = int(v)
    fu = u - j
    fv = v - i
    k = i * W + j
    return (1 - fv) * ((1 - fu) * t[k] + fu * t[k + 1]) + fv * ((1 - fu) * t[k + W] + fu * t[k + W + 1])


@_jit
def _segment_free(t, W, nx, ny, h, inv_h, x0, y0, x1, y1):
    """Whether the segment from (x0, y0), a point in a free cell, to (x1, y1) (m) crosses only free cells.

    A scalar grid traversal (Amanatides & Woo) with the same rules as
    :meth:`ConfigSpace.segments_free`: a cell touched only at a corner is
    not crossed.  Meant for the short steps of the descent, where the end is
    usually in the same or the next cell.
    """
    if not (0.0 <= x1 < nx * h and 0.0 <= y1 < ny * h):
        return False
    u0 = x0 * inv_h
    v0 = y0 * inv_h
    u1 = x1 * inv_h
    v1 = y1 * inv_h
    j = int(u0)
    i = int(v0)
    j1 = int(u1)
    i1 = int(v1)
    if j == j1 and i == i1:
        return True
    if t[(i1 + 2) * W + j1 + 2] >= BIG:
        return False
    if abs(j1 - j) + abs(i1 - i) == 1:
        return True
    du = u1 - u0
    dv = v1 - v0
    sj = 1 if du > 0 else -1
    si = 1 if dv > 0 else -1
    tx = ((j + (1 if du > 0 else 0)) - u0) / du if du != 0.0 else math.inf
    ty = ((i + (1 if dv > 0 else 0)) - v0) / dv if dv != 0.0 else math.inf
    dtx = abs(1 / du) if du != 0.0 else math.inf
    dty = abs(1 / dv) if dv != 0.0 else math.inf
    for _ in range(abs(j1 - j) + abs(i1 - i)):
        if abs(tx - ty) <= 1e-9:  # through a grid vertex: diagonally, corner cells untouched
            j += sj
            i += si
            tx += dtx
            ty += dty
        elif tx < ty:
            j += sj
            tx += dtx
        else:
            i += si
            ty += dty
        if i == i1 and j == j1:
            return True
        if t[(i + 2) * W + j + 2] >= BIG:
            return False
    return True


@_jit
def _circle_step(t, W, nx, ny, h, inv_h, x, y, t_cur):
    """The lowest arrival time below ``t_cur`` on a circle of two cells reachable in a straight line.

    Returns (found, x, y, t).
    """
    best_t = t_cur
    found = False
    bx = by = 0.0
    for e in range(CIRCLE_X.shape[0]):
        qx = x + 2 * h * CIRCLE_X[e]
        qy = y + 2 * h * CIRCLE_Y[e]
        tq = _t_at(t, W, inv_h, qx, qy)
        if tq < best_t and _segment_free(t, W, nx, ny, h, inv_h, x, y, qx, qy):
            best_t = tq
            bx = qx
            by = qy
            found = True
    return found, bx, by, best_t


@_jit
def trace(t, W, nx, ny, h, start_x, start_y, goal_x, goal_y, t_start, step):
    """The descent from the start to the goal: (points, fallbacks, ridge steps, reached).

    ``points`` are the positions visited and, when the goal was reached, the
    goal; ``t_start`` is the arrival time of the start's cell (finite).
    """
    inv_h = 1.0 / h
    ds = step * h
    near_r2 = (1.5 * h) ** 2
    max_steps = int(4 * max(t_start, 0.0) / ds) + 8 * (nx + ny)
    pts = np.empty((max_steps + 2, 2))
    x = start_x
    y = start_y
    pts[0, 0] = x
    pts[0, 1] = y
    npts = 1
    fallbacks = 0
    ridge_steps = 0
    # Ridges are searched for actively only where a path can start on one: at
    # the start and after a fallback or ridge move.  Elsewhere, a step that
    # does not lower the arrival time (the averaged gradient running along a
    # ridge that has grown sharp) triggers the same circle search.
    ridge_watch = RIDGE_WATCH
    t_cur = _t_at(t, W, inv_h, x, y)
    reached = False
    for _ in range(max_steps):
        dgx = goal_x - x
        dgy = goal_y - y
        if dgx * dgx + dgy * dgy <= near_r2 and _segment_free(t, W, nx, ny, h, inv_h, x, y, goal_x, goal_y):
            reached = True
            break
        u = x * inv_h + 1.5
        v = y * inv_h + 1.5
        j = int(u)
        i = int(v)
        fu = u - j
        fv = v - i
        k = i * W + j
        c0 = t[k]
        c1 = t[k + 1]
        c2 = t[k + W]
        c3 = t[k + W + 1]
        near = c0 >= BIG or c1 >= BIG or c2 >= BIG or c3 >= BIG
        found = False
        qx = qy = tq = 0.0
        if not near and ridge_watch == 0:
            # open space: the gradient of the bilinear interpolant of the quad
            gx = (1 - fv) * (c1 - c0) + fv * (c3 - c2)
            gy = (1 - fu) * (c2 - c0) + fu * (c3 - c1)
        else:
            # the upwind gradient at the quad's corners (0 = (i, j), 1 = (i, j+1), 2 = (i+1, j), 3 = (i+1, j+1))
            l0 = t[k - 1]
            r1 = t[k + 2]
            l2 = t[k + W - 1]
            r3 = t[k + W + 2]
            d0 = t[k - W]
            d1 = t[k - W + 1]
            u2 = t[k + 2 * W]
            u3 = t[k + 2 * W + 1]
            a0 = _up(c0, l0, c1)
            a1 = _up(c1, c0, r1)
            a2 = _up(c2, l2, c3)
            a3 = _up(c3, c2, r3)
            b0 = _up(c0, d0, c2)
            b1 = _up(c1, d1, c3)
            b2 = _up(c2, c0, u2)
            b3 = _up(c3, c1, u3)
            if ridge_watch:
                ridge_watch -= 1
                n0 = math.hypot(a0, b0)
                n1 = math.hypot(a1, b1)
                n2 = math.hypot(a2, b2)
                n3 = math.hypot(a3, b3)
                # divergence (1/cell) of the unit descent directions -g/|g| over the quad
                if n0 != 0.0 and n1 != 0.0 and n2 != 0.0 and n3 != 0.0 and 0.5 * (
                    a0 / n0 - a1 / n1 + a2 / n2 - a3 / n3 + b0 / n0 + b1 / n1 - b2 / n2 - b3 / n3
                ) > RIDGE_DIVERGENCE:
                    found, qx, qy, tq = _circle_step(t, W, nx, ny, h, inv_h, x, y, t_cur)
            # near obstacles: the interpolated upwind gradient never points into a blocked cell
            w00 = (1 - fu) * (1 - fv)
            w01 = fu * (1 - fv)
            w10 = (1 - fu) * fv
            w11 = fu * fv
            gx = w00 * a0 + w01 * a1 + w10 * a2 + w11 * a3
            gy = w00 * b0 + w01 * b1 + w10 * b2 + w11 * b3
        if not found:
            norm = math.hypot(gx, gy)
            if norm > 0:
                sx = x - ds * gx / norm
                sy = y - ds * gy / norm
                if _segment_free(t, W, nx, ny, h, inv_h, x, y, sx, sy):
                    ts = _t_at(t, W, inv_h, sx, sy)
                    if ts < t_cur:
                        x = sx
                        y = sy
                        t_cur = ts
                        pts[npts, 0] = x
                        pts[npts, 1] = y
                        npts += 1
                        continue
            found, qx, qy, tq = _circle_step(t, W, nx, ny, h, inv_h, x, y, t_cur)
        if found:
            x = qx
            y = qy
            t_cur = tq
            pts[npts, 0] = x
            pts[npts, 1] = y
            npts += 1
            ridge_steps += 1
            ridge_watch = RIDGE_WATCH
            continue
        # discrete steepest descent among this cell's and its neighbours' centres
        fallbacks += 1
        ridge_watch = RIDGE_WATCH
        kc = int(y * inv_h + 2.0) * W + int(x * inv_h + 2.0)
        best = t_cur
        bk = -1
        if t[kc] < best:
            best = t[kc]
            bk = kc
        for di in range(-1, 2):
            for dj in range(-1, 2):
                if di == 0 and dj == 0:
                    continue
                kn = kc + di * W + dj
                if t[kn] < best:
                    if di != 0 and dj != 0 and not (t[kc + di * W] < BIG and t[kc + dj] < BIG):
                        continue  # no corner cutting
                    best = t[kn]
                    bk = kn
        if bk < 0:
            reached = True  # bottom of the goal basin: the goal lies in this free cell
            break
        x = ((bk % W) - 1.5) * h
        y = ((bk // W) - 1.5) * h
        t_cur = best
        pts[npts, 0] = x
        pts[npts, 1] = y
        npts += 1
    if reached:
        pts[npts, 0] = goal_x
        pts[npts, 1] = goal_y
        npts += 1
    return pts[:npts], fallbacks, ridge_steps, reached
