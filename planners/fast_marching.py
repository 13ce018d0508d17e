"""Fast-marching travel times and the descent that turns them into paths.

Shared by FMM (unit speed) and FM² (speed from obstacle clearance).  The
arrival time ``T`` of a front started at the goal is scikit-fmm's
``travel_time`` over the free cells of a :class:`~planners.grid.ConfigSpace`
(occupied cells are masked, second-order scheme); the path is the descent of
``T`` from the start, at sub-cell resolution, ending exactly at the goal.

:func:`travel_time` is the whole field (scikit-fmm itself).  A start-goal
query needs less: :class:`FrontMarch` (and :func:`plan`) march the same scheme
in compiled code (:mod:`planners._marching`), value for value, and stop once
the start and every cell the descent reads are accepted; the path is the one
the full field gives.  The cost is the number of cells accepted: those whose
arrival time is below the start's, and a band of a few cells around the path
(docs/performance.md).

In open space the descent follows the gradient of the bilinear interpolant
of ``T``; next to obstacles it follows the interpolated *upwind* gradient
(one-sided differences towards the smaller neighbour, as the fast-marching
scheme itself uses), which never points into a blocked cell, and a step that
would still enter one falls back to the discrete steepest-descent neighbour.
Gradients are read lazily around the path only (compiled,
:mod:`planners._descent`), so the descent costs a few microseconds per step.
"""

from __future__ import annotations

import math

import numpy as np
import skfmm

from .errors import NoPathFound
from .grid import ConfigSpace

__all__ = ["FrontMarch", "descend", "plan", "travel_time", "warm_up"]

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


_BIG = 1e30  # arrival time standing for "blocked" in the descent's padded grid (finite: bilinear weights of 0 stay 0)
#: How far (Chebyshev, cells) from the cell of each of its positions the descent reads arrival times
_READ_RADIUS = 3
_FROZEN, _MASK = 2, 3  # cell states of planners._marching (checked by tests/test_fast_marching.py)


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
    ny, nx = space.free.shape
    tp = np.full((ny + 4, nx + 4), _BIG)
    np.minimum(t, _BIG, out=tp[2:-2, 2:-2])
    pts, counters, failure = _trace(space, tp.ravel(), t_start, start, goal, step)
    if failure:
        raise NoPathFound(failure)
    return pts, counters


def _trace(
    space: ConfigSpace, tp: np.ndarray, t_start: float, start: np.ndarray, goal: np.ndarray, step: float
) -> tuple[np.ndarray, dict[str, int], str | None]:
    """The descent on the padded, flattened grid ``tp`` (:mod:`planners._descent`).

    Returns the points (the positions visited, then the goal), the counters,
    and None; or, when it fails, the positions visited, the counters and why.
    """
    from ._descent import trace  # numba loads here, not when the planners are imported

    ny, nx = space.free.shape
    pts, fallbacks, ridge_steps, reached = trace(tp, nx + 4, nx, ny, space.resolution, float(start[0]),
                                                 float(start[1]), float(goal[0]), float(goal[1]), t_start,
                                                 float(step))
    counters = {"descent_steps": len(pts) - 1 - reached, "descent_fallbacks": fallbacks,
                "descent_ridge_steps": ridge_steps}
    if reached:
        return pts, counters, None
    max_steps = len(pts) - 1
    return pts, counters, f"fast-marching descent did not reach the goal within {max_steps} steps"


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
    whose arrival time is below about the start's, plus the band.  One
    instance is for one thread at a time.
    """

    def __init__(self, space: ConfigSpace, goal: np.ndarray, speed: np.ndarray | None = None) -> None:
        # numba loads here, not when the planners are imported
        from ._marching import init_grid, march, start_front, want_band

        self._kernels = march, want_band
        self.space = space
        h = self.h = space.resolution
        ny, nx = space.free.shape
        H, W = self.H, self.W = ny + 4, nx + 4
        self.flag = np.empty(H * W, dtype=np.int8)
        self.t = np.empty(H * W)
        init_grid(space.free, self.flag, self.t)
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
            self.flag[slow.ravel()] = _MASK
        self.sgn = np.zeros(H * W, dtype=np.uint8)
        cap = H * W
        self.hkey = np.empty(cap + 8)
        self.hkey[:8] = np.inf
        self.hcell = np.empty(cap + 8, dtype=np.int32)
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
        n = start_front(W, self.flag, self.t, self.sgn, h, level, speed_win, k0, seeds)
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
        self._kernels[0](self.W, self.flag, self.t, self.sgn, *self.sgn_range, self.inv_s2, self.unit,
                       1.0 / self.h / self.h, self.hkey, self.hcell, self.pos, self.state, self.want, self.batch,
                       self.seeds)

    def _reach(self, cells: np.ndarray, radius: int) -> bool:
        """March until every free cell within ``radius`` (Chebyshev) of the padded ``cells`` is accepted.

        Returns False when there was nothing to march for: each of those cells
        was accepted, blocked, or is unreachable (the front has stopped).
        """
        if self.complete:
            return False
        wanted = self._kernels[1](self.flag, self.W, self.H, cells, radius, self.want)
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
        return self.arrival()

    def arrival(self) -> np.ndarray:
        """The arrival times computed so far, ``(ny, nx)``, as :func:`travel_time`'s; ``+inf`` elsewhere."""
        t = self.t.reshape(self.H, self.W)[2:-2, 2:-2].copy()
        t[self.flag.reshape(self.H, self.W)[2:-2, 2:-2] != _FROZEN] = np.inf
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
        if self.flag[ks_t] != _FROZEN:
            raise NoPathFound("the goal cannot be reached from the start")
        self._reach(ks, _READ_RADIUS)
        descents = 0
        k_in, level = self._inside
        while True:
            descents += 1
            marched = self.t[k_in]
            self.t[k_in] = level
            try:
                pts, counters, failure = _trace(self.space, self.t, float(self.t[ks_t]), start, goal, step)
            finally:
                self.t[k_in] = marched
            visited = pts[: len(pts) - (failure is None)]
            if not self._reach(self._cells(visited), _READ_RADIUS):
                break  # every value the descent read was final: it is the descent of the full field
        if failure:
            raise NoPathFound(failure)
        counters["cells_accepted"] = self.accepted
        counters["descents"] = descents
        return pts, counters


def plan(
    space: ConfigSpace, start: np.ndarray, goal: np.ndarray, speed: np.ndarray | None = None, *, step: float = 1.0
) -> tuple[np.ndarray, dict[str, int]]:
    """``descend(space, travel_time(space, goal, speed), start, goal, step=step)``, marching only what it needs."""
    return FrontMarch(space, goal, speed).path(start, goal, step=step)


def warm_up() -> None:
    """Load the compiled kernels of the built-in planners (compiling them the first time, a few seconds) with
    tiny queries: the march and descent, FM²'s chord search, PRM's roadmap kernels and Theta*'s search.

    Worker processes call it before their first job, so that a plan's time is
    the planning alone (without it the study's first PRM plans took 0.1-0.3 s: the kernels' loading).
    """
    import planners._roadmap as roadmap

    from .anyangle import theta_star
    from .environment import load_environment
    from .grid import config_space

    from ._band import band_chain

    space = config_space(load_environment({"name": "warm-up", "size": [0.2, 0.2], "blocks": []}), 0.0, 0.02)
    plan(space, np.array([0.03, 0.03]), np.array([0.17, 0.15]))
    ny, nx = space.free.shape  # FM²'s chord search (planners.fm2.band_shortcut), on three corners and no block
    band_chain(np.array([[0.03, 0.03], [0.1, 0.05], [0.17, 0.15]]), np.full(3, 0.03), np.zeros((0, 6)), 0.2, 0.2,
               np.ascontiguousarray(space.free.ravel(), dtype=np.uint8), nx, ny, 1.0 / space.resolution, 64)
    roadmap.warm()
    theta_star(space, np.array([0.03, 0.03]), np.array([0.17, 0.15]))
