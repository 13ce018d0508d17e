"""Fast-marching travel times and the descent that turns them into paths.

Shared by FMM (unit speed) and FM² (speed from obstacle clearance).  The
arrival time ``T`` is computed from the goal with ``skfmm.travel_time`` over
the free cells of a :class:`~planners.grid.ConfigSpace` (occupied cells are
masked); the path is the descent of ``T`` from the start, at sub-cell
resolution, ending exactly at the goal.

In open space the descent follows the gradient of the bilinear interpolant
of ``T``; next to obstacles it follows the interpolated *upwind* gradient
(one-sided differences towards the smaller neighbour, as the fast-marching
scheme itself uses), which never points into a blocked cell, and a step that
would still enter one falls back to the discrete steepest-descent neighbour.
Gradients are read lazily around the path only, so the cost beyond
``skfmm.travel_time`` is a few microseconds per step (see docs/performance.md).
"""

from __future__ import annotations

import math

import numpy as np
import skfmm

from .errors import NoPathFound
from .grid import ConfigSpace

__all__ = ["FrontMarch", "descend", "plan", "travel_time"]

_CIRCLE = [complex(math.cos(a), math.sin(a)) for a in np.linspace(0, 2 * math.pi, 32, endpoint=False)]
_RIDGE_WATCH = 8  # steps checked for a ridge after the start, a fallback or a ridge step
_RIDGE_DIVERGENCE = 0.3  # 1/cell; about the angle (rad) between the two ways round on a ridge
_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def travel_time(space: ConfigSpace, goal: np.ndarray, speed: np.ndarray | None = None) -> np.ndarray:
    """Arrival time (s, or m at unit speed) of a front started at ``goal`` (m), ``(ny, nx)``.

    Occupied and unreachable cells are ``+inf``.  ``speed`` (m/s, ``(ny, nx)``,
    > 0 on free cells) defaults to 1.  Inside the one-cell circle around the
    goal where the front starts, ``T`` is minus the distance to that circle, so
    ``T`` keeps decreasing all the way to the goal.
    """
    h = space.resolution
    ny, nx = space.free.shape
    xs = (np.arange(nx) + 0.5) * h - goal[0]
    ys = (np.arange(ny) + 0.5) * h - goal[1]
    # zero level set: a circle of one cell around the goal, so it always crosses cell centres
    level = np.hypot(xs[None, :], ys[:, None]) - h
    phi = np.ma.MaskedArray(level, mask=~space.free)
    if speed is None:
        speed = np.ones((ny, nx))
    out = skfmm.travel_time(phi, speed, dx=h)
    t = np.where(np.ma.getmaskarray(out), np.inf, np.ma.getdata(out))
    inside = (level < 0) & space.free
    t[inside] = level[inside]
    return t


_BIG = 1e30  # arrival time standing for "blocked": finite, so bilinear weights of 0 stay 0


def _up(c: float, lo: float, hi: float) -> float:
    """Upwind difference at a cell of time ``c`` with neighbours ``lo`` (before) and ``hi`` (after)."""
    if c >= _BIG:
        return 0.0
    if lo <= hi:
        return c - lo if c > lo else 0.0
    return hi - c if c > hi else 0.0


class _Descent:
    """Scalar reads of a padded, flattened arrival-time grid.

    The grid is padded by two blocked cells so that the 4 x 4 stencil around
    any interpolation quad exists without clamping; ``k = row * W + col`` is
    the flat index of the padded grid.  The upwind gradient is evaluated
    lazily at the four corners of the quad the path is in (12 reads), which
    on large grids is far cheaper than computing it everywhere.
    """

    def __init__(self, space: ConfigSpace, t: np.ndarray, *, padded: bool = False) -> None:
        """``t``: the ``(ny, nx)`` arrival times, or (``padded``) the flat padded array itself."""
        h = space.resolution
        self.h, self.inv_h = h, 1.0 / h
        ny, nx = self.ny, self.nx = space.free.shape
        self.W = nx + 4
        if padded:
            self.t = t.item
        else:
            tp = np.full((ny + 4, nx + 4), _BIG)
            np.minimum(t, _BIG, out=tp[2:-2, 2:-2])
            self.t = tp.ravel().item

    def cell(self, x: float, y: float) -> int:
        """Padded flat index of the cell containing (x, y) (m), inside the field."""
        return int(y * self.inv_h + 2.0) * self.W + int(x * self.inv_h + 2.0)

    def is_free(self, x: float, y: float) -> bool:
        return 0.0 <= x < self.nx * self.h and 0.0 <= y < self.ny * self.h and self.t(self.cell(x, y)) < _BIG

    def segment_free(self, x0: float, y0: float, x1: float, y1: float) -> bool:
        """Whether the segment from (x0, y0), a point in a free cell, to (x1, y1) (m) crosses only free cells.

        A scalar grid traversal (Amanatides & Woo) with the same rules as
        :meth:`ConfigSpace.segments_free`: a cell touched only at a corner is
        not crossed.  Meant for the short steps of the descent, where the end
        is usually in the same or the next cell.
        """
        if not (0.0 <= x1 < self.nx * self.h and 0.0 <= y1 < self.ny * self.h):
            return False
        inv, W, ti = self.inv_h, self.W, self.t
        u0, v0, u1, v1 = x0 * inv, y0 * inv, x1 * inv, y1 * inv
        j, i, j1, i1 = int(u0), int(v0), int(u1), int(v1)
        if j == j1 and i == i1:
            return True
        if ti((i1 + 2) * W + j1 + 2) >= _BIG:
            return False
        if abs(j1 - j) + abs(i1 - i) == 1:
            return True
        du, dv = u1 - u0, v1 - v0
        sj, si = (1 if du > 0 else -1), (1 if dv > 0 else -1)
        tx = ((j + (du > 0)) - u0) / du if du else math.inf
        ty = ((i + (dv > 0)) - v0) / dv if dv else math.inf
        dtx, dty = (abs(1 / du) if du else math.inf), (abs(1 / dv) if dv else math.inf)
        for _ in range(abs(j1 - j) + abs(i1 - i)):
            if abs(tx - ty) <= 1e-9:  # through a grid vertex: diagonally, corner cells untouched
                j, i, tx, ty = j + sj, i + si, tx + dtx, ty + dty
            elif tx < ty:
                j, tx = j + sj, tx + dtx
            else:
                i, ty = i + si, ty + dty
            if i == i1 and j == j1:
                return True
            if ti((i + 2) * W + j + 2) >= _BIG:
                return False
        return True

    def t_at(self, x: float, y: float) -> float:
        """Bilinear arrival time at (x, y) (m)."""
        u, v = x * self.inv_h + 1.5, y * self.inv_h + 1.5
        j, i = int(u), int(v)
        fu, fv = u - j, v - i
        k, ti, W = i * self.W + j, self.t, self.W
        return (1 - fv) * ((1 - fu) * ti(k) + fu * ti(k + 1)) + fv * ((1 - fu) * ti(k + W) + fu * ti(k + W + 1))

    def gradient(self, k: int) -> tuple[float, float, float, float, float, float, float, float, bool]:
        """Upwind gradient at the quad with lower-left padded index ``k``: (gx0..3, gy0..3, near).

        Corners are 0 = (i, j), 1 = (i, j+1), 2 = (i+1, j), 3 = (i+1, j+1);
        ``near`` tells whether any cell of the stencil is blocked.
        """
        ti, W = self.t, self.W
        c0, c1, c2, c3 = ti(k), ti(k + 1), ti(k + W), ti(k + W + 1)
        l0, r1, l2, r3 = ti(k - 1), ti(k + 2), ti(k + W - 1), ti(k + W + 2)
        d0, d1, u2, u3 = ti(k - W), ti(k - W + 1), ti(k + 2 * W), ti(k + 2 * W + 1)
        near = max(c0, c1, c2, c3, l0, r1, l2, r3, d0, d1, u2, u3) >= _BIG
        return (
            _up(c0, l0, c1), _up(c1, c0, r1), _up(c2, l2, c3), _up(c3, c2, r3),
            _up(c0, d0, c2), _up(c1, d1, c3), _up(c2, c0, u2), _up(c3, c1, u3),
            near,
        )


def descend(
    space: ConfigSpace,
    t: np.ndarray,
    start: np.ndarray,
    goal: np.ndarray,
    *,
    step: float = 1.0,
) -> tuple[np.ndarray, dict[str, int]]:
    """Descend ``t`` from ``start`` to ``goal``; returns the ``(N, 2)`` path (m) and counters.

    ``step`` is the step length in cells, in (0, 1].  In open space the
    direction is the gradient of the bilinear interpolant of ``t``; next to
    obstacles it is the interpolated upwind gradient, which never points into
    a blocked cell.  Every step must cross only free cells (exact grid
    traversal) and strictly decrease the interpolated arrival time, so the
    descent cannot cycle.  Where a step fails — on a ridge of ``t``, two
    equally fast ways round an obstacle, the averaged gradient runs along the
    ridge — the lowest arrival time on a circle of two cells picks one way;
    failing that, the descent moves to the neighbouring cell centre with the
    lowest arrival time.  Ridges are also looked for actively (the unit
    descent directions at the quad's corners diverge) where a path can start
    on one: at the start and after such moves.  The loop is over steps along
    the path (about one per cell travelled), never over grid cells.
    """
    if not 0 < step <= 1:
        raise ValueError("`step` must be in (0, 1] cells")
    iy, ix = space.grid.cell_of(start[None, :])
    t_start = float(t[iy[0], ix[0]])
    if not math.isfinite(t_start):
        raise NoPathFound("the goal cannot be reached from the start")
    pts, counters, failure = _trace(_Descent(space, t), t_start, start, goal, step)
    if failure:
        raise NoPathFound(failure)
    return np.array(pts), counters


def _trace(
    d: _Descent, t_start: float, start: np.ndarray, goal: np.ndarray, step: float
) -> tuple[list[tuple[float, float]], dict[str, int], str | None]:
    """The descent of :func:`descend` from ``start`` (arrival time ``t_start``, finite) to ``goal``.

    Returns the points (the positions visited, then the goal), the counters,
    and None; or, when it fails, the positions visited, the counters and
    why.  Every value it reads lies within 3 cells (Chebyshev) of the cell
    of a visited position (column ``int(x * inv_h)``, row ``int(y * inv_h)``).
    """
    h = d.h
    tv, W, inv_h = d.t, d.W, d.inv_h
    goal_x, goal_y = float(goal[0]), float(goal[1])
    x, y = float(start[0]), float(start[1])
    pts = [(x, y)]
    near_r2 = (1.5 * h) ** 2
    ds = step * h
    max_steps = int(4 * max(t_start, 0.0) / ds) + 8 * (d.nx + d.ny)
    fallbacks = ridge_steps = 0
    # Ridges are searched for actively only where a path can start on one: at
    # the start and after a fallback or ridge move.  Elsewhere, a step that
    # does not lower the arrival time (the averaged gradient running along a
    # ridge that has grown sharp) triggers the same circle search.
    ridge_watch = _RIDGE_WATCH
    t_cur = d.t_at(x, y)

    def circle_step() -> tuple[float, float, float] | None:
        best_t, best_q = t_cur, None
        for e in _CIRCLE:
            qx, qy = x + 2 * h * e.real, y + 2 * h * e.imag
            tq = d.t_at(qx, qy)
            if tq < best_t and d.segment_free(x, y, qx, qy):
                best_t, best_q = tq, (qx, qy, tq)
        return best_q

    for _ in range(max_steps):
        dgx, dgy = goal_x - x, goal_y - y
        if dgx * dgx + dgy * dgy <= near_r2 and d.segment_free(x, y, goal_x, goal_y):
            break
        u, v = x * inv_h + 1.5, y * inv_h + 1.5
        j, i = int(u), int(v)
        fu, fv = u - j, v - i
        k = i * W + j
        c0, c1, c2, c3 = tv(k), tv(k + 1), tv(k + W), tv(k + W + 1)
        near = c0 >= _BIG or c1 >= _BIG or c2 >= _BIG or c3 >= _BIG
        q = None
        if not near and not ridge_watch:
            # open space: the gradient of the bilinear interpolant of the quad
            gx = (1 - fv) * (c1 - c0) + fv * (c3 - c2)
            gy = (1 - fu) * (c2 - c0) + fu * (c3 - c1)
        else:
            a0, a1, a2, a3, b0, b1, b2, b3, near = d.gradient(k)
            if ridge_watch:
                ridge_watch -= 1
                n0, n1, n2, n3 = math.hypot(a0, b0), math.hypot(a1, b1), math.hypot(a2, b2), math.hypot(a3, b3)
                # divergence (1/cell) of the unit descent directions -g/|g| over the quad
                if n0 and n1 and n2 and n3 and 0.5 * (
                    a0 / n0 - a1 / n1 + a2 / n2 - a3 / n3 + b0 / n0 + b1 / n1 - b2 / n2 - b3 / n3
                ) > _RIDGE_DIVERGENCE:
                    q = circle_step()
            # near obstacles: the interpolated upwind gradient never points into a blocked cell
            w00, w01, w10, w11 = (1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv
            gx = w00 * a0 + w01 * a1 + w10 * a2 + w11 * a3
            gy = w00 * b0 + w01 * b1 + w10 * b2 + w11 * b3
        if q is None:
            norm = math.hypot(gx, gy)
            if norm > 0:
                qx, qy = x - ds * gx / norm, y - ds * gy / norm
                if d.segment_free(x, y, qx, qy):
                    tq = d.t_at(qx, qy)
                    if tq < t_cur:
                        x, y, t_cur = qx, qy, tq
                        pts.append((x, y))
                        continue
            q = circle_step()
        if q is not None:
            x, y, t_cur = q
            pts.append((x, y))
            ridge_steps += 1
            ridge_watch = _RIDGE_WATCH
            continue
        # discrete steepest descent among this cell's and its neighbours' centres
        fallbacks += 1
        ridge_watch = _RIDGE_WATCH
        kc = d.cell(x, y)
        best, bk = t_cur, -1
        if tv(kc) < best:
            best, bk = tv(kc), kc
        for di, dj in _NEIGHBOURS:
            kn = kc + di * W + dj
            if tv(kn) < best:
                if di and dj and not (tv(kc + di * W) < _BIG and tv(kc + dj) < _BIG):
                    continue  # no corner cutting
                best, bk = tv(kn), kn
        if bk < 0:
            break  # bottom of the goal basin: the goal lies in this free cell
        x, y, t_cur = ((bk % W) - 1.5) * h, ((bk // W) - 1.5) * h, best
        pts.append((x, y))
    else:
        counters = {"descent_steps": len(pts) - 1, "descent_fallbacks": fallbacks, "descent_ridge_steps": ridge_steps}
        return pts, counters, f"fast-marching descent did not reach the goal within {max_steps} steps"
    pts.append((goal_x, goal_y))
    counters = {"descent_steps": len(pts) - 2, "descent_fallbacks": fallbacks, "descent_ridge_steps": ridge_steps}
    return pts, counters, None


#: How far (Chebyshev, cells) from the cell of each of its positions the descent reads arrival times (see _trace)
_READ_RADIUS = 3


class FrontMarch:
    """The front of :func:`travel_time` from ``goal``, marched only as far as the queries need.

    A heap-based fast marching (compiled, :mod:`planners._marching`) with
    scikit-fmm's second-order scheme: every arrival time it computes equals
    ``skfmm.travel_time``'s (the same floating-point operations in the same
    order), so a descent that reads only computed values follows exactly the
    path it follows on the full field.  The march stops as soon as the cells
    asked for are accepted and resumes from there when asked for more;
    :meth:`path` asks for the start, the band the descent reads around it and,
    after each descent, the band around the path, and descends again if that
    band was not complete.  One ``FrontMarch`` answers many starts of the same
    goal (each extends the front only as far as it needs); :meth:`field` is
    the whole field, as :func:`travel_time`.

    The cost is the number of cells accepted, :attr:`accepted`: the cells
    whose arrival time is below about the start's, plus the band.
    """

    def __init__(self, space: ConfigSpace, goal: np.ndarray, speed: np.ndarray | None = None) -> None:
        from . import _marching as km  # numba loads here, not when the planners are imported

        self._km = km
        self.space = space
        h = self.h = space.resolution
        ny, nx = space.free.shape
        H, W = self.H, self.W = ny + 4, nx + 4
        self.flag = np.empty(H * W, dtype=np.int8)
        self.t = np.empty(H * W)
        km.init_grid(space.free, self.flag, self.t)
        self.unit = speed is None
        if self.unit:
            self.inv_s2 = np.ones(1)
        else:
            speed = np.asarray(speed, dtype=float)
            inv_s2 = np.ones((H, W))
            np.multiply(speed, speed, out=inv_s2[2:-2, 2:-2])
            np.divide(1.0, inv_s2[2:-2, 2:-2], out=inv_s2[2:-2, 2:-2])  # as scikit-fmm's 1 / pow(speed, 2)
            self.inv_s2 = inv_s2.ravel()
            slow = np.zeros((H, W), dtype=bool)
            slow[2:-2, 2:-2] = speed < np.finfo(float).eps  # scikit-fmm masks speeds below the machine epsilon
            self.flag[slow.ravel()] = km.MASK
        self.sgn = np.zeros(H * W, dtype=np.uint8)
        cap = H * W
        self.hkey = np.empty(cap + 4)
        self.hkey[:4] = np.inf
        self.hcell = np.empty(cap, dtype=np.int32)
        self.pos = np.empty(cap, dtype=np.int32)
        self.batch = np.empty(cap, dtype=np.int32)
        self.want = np.zeros(cap, dtype=np.uint8)
        self.state = np.zeros(4, dtype=np.int64)  # heap size, wanted cells left, cells accepted, seeds done
        # phi (as travel_time's) on a window around the goal, which holds every cell with phi <= 0 and their
        # neighbours; the cells inside the one-cell circle get -distance to it for the descent
        gx, gy = float(goal[0]), float(goal[1])
        ci = min(max(math.floor(gy / h), 0), ny - 1)
        cj = min(max(math.floor(gx / h), 0), nx - 1)
        i0, i1, j0, j1 = max(ci - 3, 0), min(ci + 4, ny), max(cj - 3, 0), min(cj + 4, nx)
        xs = (np.arange(j0, j1) + 0.5) * h - gx
        ys = (np.arange(i0, i1) + 0.5) * h - gy
        level = np.hypot(xs[None, :], ys[:, None]) - h
        speed_win = np.ones_like(level) if speed is None else np.array(speed[i0:i1, j0:j1], dtype=float)
        k0 = (i0 + 2) * W + j0 + 2
        seeds = np.empty((i1 - i0 + 2) * (j1 - j0 + 2), dtype=np.int64)
        n = km.start_front(W, self.flag, self.t, self.sgn, h, level, speed_win, k0, seeds)
        if n < 0:
            raise ValueError("the array phi contains no zero contour (no zero level set)")
        self.seeds = seeds[:n]
        self.sgn_range = (k0, k0 + (i1 - i0 - 1) * W + (j1 - j0 - 1))
        ii, jj = np.nonzero((level < 0) & space.free[i0:i1, j0:j1])
        self._inside = ((ii + i0 + 2) * W + jj + j0 + 2, level[ii, jj])

    @property
    def accepted(self) -> int:
        """Cells accepted (frozen) by the march so far, the initial front excluded."""
        return int(self.state[2])

    @property
    def complete(self) -> bool:
        """Whether the front has stopped: every reachable cell is accepted."""
        return self.state[0] == 0 and self.state[3] == len(self.seeds)

    def _march(self) -> None:
        self._km.march(self.W, self.flag, self.t, self.sgn, *self.sgn_range, self.inv_s2, self.unit,
                       1.0 / self.h / self.h, self.hkey, self.hcell, self.pos, self.state, self.want, self.batch,
                       self.seeds)

    def _reach(self, cells: np.ndarray, radius: int) -> bool:
        """March until every free cell within ``radius`` (Chebyshev) of the padded ``cells`` is accepted.

        Returns False when there was nothing to march for: each of those cells
        was accepted, blocked, or is unreachable (the front has stopped).
        """
        if self.complete:
            return False
        wanted = self._km.want_band(self.flag, self.W, self.H, cells, radius, self.want)
        if not wanted:
            return False
        self.state[1] += wanted
        self._march()
        return True

    def field(self) -> np.ndarray:
        """The whole field, ``(ny, nx)``: :func:`travel_time`'s array (marches what is left)."""
        if not self.complete:
            self.state[1] = 2**62  # more wanted cells than there are: march until the front stops
            self._march()
        t = self.t.reshape(self.H, self.W)[2:-2, 2:-2].copy()
        t[self.flag.reshape(self.H, self.W)[2:-2, 2:-2] != self._km.FROZEN] = np.inf
        k, level = self._inside
        t.ravel()[self._unpad(k)] = level
        return t

    def _unpad(self, k: np.ndarray) -> np.ndarray:
        i, j = np.divmod(k, self.W)
        return (i - 2) * (self.W - 4) + (j - 2)

    def _cells(self, pts: np.ndarray) -> np.ndarray:
        """Padded cells of positions (m), as the descent computes them."""
        inv_h = 1.0 / self.h
        j = np.clip((pts[:, 0] * inv_h).astype(np.int64), -2, self.W - 3)
        i = np.clip((pts[:, 1] * inv_h).astype(np.int64), -2, self.H - 3)
        return (i + 2) * self.W + j + 2

    def path(self, start: np.ndarray, goal: np.ndarray, *, step: float = 1.0) -> tuple[np.ndarray, dict[str, int]]:
        """:func:`descend` from ``start`` on the field, computing only what the descent reads.

        The same path and counters as ``descend(space, travel_time(...), start, goal)``,
        plus ``cells_accepted`` (so far, for this goal) and ``descents``.
        """
        if not 0 < step <= 1:
            raise ValueError("`step` must be in (0, 1] cells")
        ks = self._cells(np.asarray(start, dtype=float)[None, :2])
        # the start cell as travel_time's t[cell_of(start)]: clipped to the grid
        iy, ix = self.space.grid.cell_of(np.asarray(start, dtype=float)[None, :2])
        ks_t = (iy[0] + 2) * self.W + ix[0] + 2
        self._reach(np.array([ks_t]), 0)
        if self.flag[ks_t] != self._km.FROZEN:
            raise NoPathFound("the goal cannot be reached from the start")
        self._reach(ks, _READ_RADIUS)
        descents = 0
        k_in, level = self._inside
        while True:
            descents += 1
            marched = self.t[k_in]
            self.t[k_in] = level
            try:
                d = _Descent(self.space, self.t, padded=True)
                pts, counters, failure = _trace(d, float(self.t[ks_t]), start, goal, step)
            finally:
                self.t[k_in] = marched
            visited = np.array(pts[: len(pts) - (failure is None)])
            if not self._reach(self._cells(visited), _READ_RADIUS):
                break  # every value the descent read was final: it is the descent of the full field
        if failure:
            raise NoPathFound(failure)
        counters["cells_accepted"] = self.accepted
        counters["descents"] = descents
        return np.array(pts), counters


def plan(
    space: ConfigSpace, start: np.ndarray, goal: np.ndarray, speed: np.ndarray | None = None, *, step: float = 1.0
) -> tuple[np.ndarray, dict[str, int]]:
    """``descend(space, travel_time(space, goal, speed), start, goal, step=step)``, marching only what it needs."""
    return FrontMarch(space, goal, speed).path(start, goal, step=step)
