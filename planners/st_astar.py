"""Space-time A*: a grid path that avoids the environment's moving obstacles at the times the robot passes.

The search runs over states (lattice point, time bucket).  The lattice has a
point every ``cell`` metres (``(i cell, j cell)``); its 8-connected moves are
those of the ``astar`` grid graph (no corner cutting) whose segments are free
in the configuration space.  The robot is modelled as moving along the path
at ``speed`` (m/s), so a move takes its length / ``speed`` seconds; the
optional ``wait`` action stays one bucket.

Where moving obstacles are is precomputed once, vectorised, as a conflict
table ``(K, ny, nx)``: obstacle positions (:func:`planners.moving.positions`)
sampled four times per bucket mark every lattice point closer than the
obstacle's radius + the robot's radius and planning margin + half a lattice
diagonal (the robot between two points) + ``clearance``; SciPy's
``maximum_filter1d`` then widens every conflict by ``time_margin_s`` both
ways, for the difference between this timing model and the executed run
(start-up, turns, the follower's corner rounding).  The heuristic is the
static shortest lattice distance to the goal (SciPy's Dijkstra on the grid
graph) over ``speed``: admissible, so the first arrival found is the
earliest under the model.  The search itself is a heap over states; the
goal must also stay clear for ``arrive_s`` after the arrival (the robot
aligns there).

**Timing on the robot.**  ``T,T,P`` carries no times: the follower drives
every path at its own speed and cannot wait.  With ``wait`` False (the
default) the plan has no waits, so its timing is only a speed profile the
follower keeps approximately (0.18 m/s is a BeBot's average along a
planned path, start-up and corners included); the plan's waypoint times are
in ``info["times_s"]``.  A plan with waits (``wait`` True) is reported
(``info["waits"]``) but executed without them: it reaches its later
waypoints early.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Sequence

import numpy as np
from scipy import ndimage
from scipy.sparse.csgraph import dijkstra

from .astar import grid_graph
from .base import Param, Planner
from .errors import NoPathFound, PlanningError
from .grid import ConfigSpace
from .moving import MovingObstacle, positions

__all__ = ["MAX_STATES", "PlanTooLarge", "SpaceTimeAStar", "TimedPath", "conflict_table", "mover_positions", "movers_table", "plan_timed",
           "without_waits"]

class PlanTooLarge(PlanningError):
    """The search the parameters ask for would not fit a planning worker's memory (:data:`MAX_STATES`)."""


_MOVES = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
#: samples of each mover per time bucket
SAMPLES_PER_BUCKET = 4
MAX_BUCKETS = 20_000
#: most (lattice point, time bucket) states a search may hold: its conflict table and closed set are a byte per
#: state each (100 MB at this bound), its open set a fraction; the 2 mm lattice of a probe asked for 17 GB
MAX_STATES = 50_000_000


@dataclass(frozen=True)
class TimedPath:
    """A disc of ``radius`` (m) at ``points`` ``(N, 2)`` (m) at ``times`` ``(N,)`` (s, non-decreasing; a
    repeated point is a wait), moving straight between them and standing at its last point afterwards."""

    points: np.ndarray
    times: np.ndarray
    radius: float

    def position(self, t: np.ndarray) -> np.ndarray:
        """Centres ``(T, 2)`` (m) at times ``t`` ``(T,)`` (s)."""
        tt = np.asarray(t, dtype=float)
        return np.column_stack([np.interp(tt, self.times, self.points[:, 0]),
                                np.interp(tt, self.times, self.points[:, 1])])


def mover_positions(obstacles: Sequence[MovingObstacle], others: Sequence[TimedPath],
                    t: np.ndarray, obstacle_time_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``(M, T, 2)`` (m) at times ``t`` (s) and radii ``(M,)`` (m) of moving obstacles, then timed paths;
    the obstacles are where they are at their own time ``obstacle_time_s + t`` (a replan mid-run)."""
    tt = np.asarray(t, dtype=float)
    centres = [positions(obstacles, tt + obstacle_time_s)] if obstacles else []
    centres += [o.position(tt)[None] for o in others]
    radii = [o.radius for o in obstacles] + [o.radius for o in others]
    return (np.concatenate(centres) if centres else np.zeros((0, len(tt), 2))), np.array(radii, dtype=float)


def conflict_table(centres: np.ndarray, radii: np.ndarray, shape: tuple[int, int], cell: float, buckets: int,
                   inflate: float, margin_buckets: int) -> np.ndarray:
    """``(buckets, ny, nx)`` bool: lattice point ``(j cell, i cell)`` (m) comes within a mover's radius +
    ``inflate`` (m) of its centre during a time bucket, widened by ``margin_buckets`` both ways.

    ``centres`` ``(M, S, 2)`` are the movers sampled :data:`SAMPLES_PER_BUCKET` times per bucket from time 0
    (sample ``s`` in bucket ``s // SAMPLES_PER_BUCKET``); ``radii`` ``(M,)``.
    """
    ny, nx = shape
    table = np.zeros((buckets, ny, nx), dtype=bool)
    if not len(centres):
        return table
    bucket = np.minimum(np.arange(centres.shape[1]) // SAMPLES_PER_BUCKET, buckets - 1)
    for m in range(len(centres)):  # a loop over the movers; samples and stencil vectorised
        reach = float(radii[m]) + inflate
        r = int(math.ceil(reach / cell))
        offs = np.arange(-r, r + 1)
        cx, cy = centres[m, :, 0], centres[m, :, 1]
        ix = np.rint(cx / cell).astype(np.int64)[:, None, None] + offs[None, None, :]
        iy = np.rint(cy / cell).astype(np.int64)[:, None, None] + offs[None, :, None]
        near = (ix * cell - cx[:, None, None]) ** 2 + (iy * cell - cy[:, None, None]) ** 2 < reach * reach
        near &= (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        kk = np.broadcast_to(bucket[:, None, None], near.shape)[near]
        table[kk, np.broadcast_to(iy, near.shape)[near], np.broadcast_to(ix, near.shape)[near]] = True
    if margin_buckets > 0:
        table = ndimage.maximum_filter1d(table.view(np.uint8), size=2 * margin_buckets + 1, axis=0,
                                         mode="nearest").astype(bool)
    return table


@lru_cache(maxsize=8)
def _lattice(space: ConfigSpace, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Free lattice points ``(ny, nx)`` and, per move of :data:`_MOVES`, whether it is free ``(8, ny, nx)``."""
    env = space.env
    nx, ny = int(math.floor(env.width / cell + 1e-9)) + 1, int(math.floor(env.height / cell + 1e-9)) + 1
    jj, ii = np.mgrid[0:ny, 0:nx]
    pts = np.column_stack([ii.ravel() * cell, jj.ravel() * cell])
    free = space.is_free(pts).reshape(ny, nx)
    edges = np.zeros((len(_MOVES), ny, nx), dtype=bool)
    for d, (dy, dx) in enumerate(_MOVES):
        ti, tj = ii + dx, jj + dy
        ok = free & (ti >= 0) & (ti < nx) & (tj >= 0) & (tj < ny)
        ok[ok] &= free[tj[ok], ti[ok]]
        if dx and dy:  # as the astar grid graph: no corner cutting
            ok[ok] &= free[jj[ok], ti[ok]] & free[tj[ok], ii[ok]]
        src = np.flatnonzero(ok.ravel())
        dst = np.column_stack([ti.ravel()[src] * cell, tj.ravel()[src] * cell])
        ok.ravel()[src] = space.segments_free(pts[src], dst)
        edges[d] = ok
    return free, edges


def _attach(space: ConfigSpace, point: np.ndarray, free: np.ndarray, cell: float) -> tuple[int, int]:
    """The free lattice point ``(j, i)`` nearest ``point`` (m) that a free segment reaches."""
    ny, nx = free.shape
    j0, i0 = int(round(point[1] / cell)), int(round(point[0] / cell))
    cand = [(j, i) for j in range(j0 - 2, j0 + 3) for i in range(i0 - 2, i0 + 3)
            if 0 <= j < ny and 0 <= i < nx and free[j, i]]
    cand.sort(key=lambda c: (math.hypot(c[1] * cell - point[0], c[0] * cell - point[1]), c))
    if cand:
        ends = np.array([[i * cell, j * cell] for j, i in cand])
        ok = space.segments_free(np.repeat(point[None, :], len(cand), axis=0), ends)
        if ok.any():
            return cand[int(np.argmax(ok))]
    raise NoPathFound(f"no free lattice point of the {cell} m space-time grid near ({point[0]:.3f}, {point[1]:.3f})")


class SpaceTimeAStar(Planner):
    """A* over (lattice point, time) that avoids the environment's moving obstacles under a speed model."""

    name = "st_astar"
    description = "space-time A* on an 8-connected lattice, avoiding moving obstacles at the robot's speed"
    parameters = (
        # bounded by what a planning worker can hold: a lattice finer than the configuration space's 1 cm grid
        # resolves nothing more, and the search's state budget (MAX_STATES) bounds the rest at planning time
        Param("cell", "m", 0.05, 0.01, 0.5, "spacing of the lattice (at least the 1 cm of the occupancy grid)"),
        Param("speed", "m/s", 0.18, 0.0, 2.0, "the speed the robot is modelled to drive the path at",
              low_exclusive=True),
        Param("time_margin_s", "s", 1.0, 0.0, 60.0, "each conflict with a moving obstacle widened by this, both ways"),
        Param("clearance", "m", 0.02, 0.0, 0.5, "extra distance kept from moving obstacles"),
        Param("wait", default=False, type="boolean", doc="whether the plan may stand still"),
        Param("arrive_s", "s", 2.0, 0.0, 60.0, "how long the goal must stay clear after the arrival"),
        Param("horizon_s", "s", 0.0, 0.0, 3600.0, "how far ahead the search looks (0: automatic)"),
    )

    def solve(self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any],
              seed: int) -> tuple[np.ndarray, dict[str, Any]]:
        timed, info = plan_timed(space, start, goal, params)
        path, times = without_waits(timed)
        info["times_s"] = [round(float(t), 4) for t in times]
        return path, info


def without_waits(timed: TimedPath) -> tuple[np.ndarray, np.ndarray]:
    """The points ``(N, 2)`` (m) of a timed path with each wait (a repeated point) kept once, and the times (s)
    the robot arrives at them: what a follower that cannot wait drives."""
    first = np.flatnonzero(np.concatenate([[True], np.hypot(*np.diff(timed.points, axis=0).T) > 1e-9]))
    path = timed.points[first]
    path[-1] = timed.points[-1]  # the exact goal
    return path, timed.times[first]


def _search(table: np.ndarray, edges: np.ndarray, h_s: np.ndarray, s_cell: tuple[int, int],
            g_cell: tuple[int, int], t0: float, dt: float, stay: int,
            wait: bool) -> tuple[list[float], list[tuple[int, int]], int]:
    """Earliest conflict-free arrival (times s, lattice points (j, i), states expanded)."""
    buckets = len(table)
    closed = np.zeros(table.shape, dtype=bool)
    k0 = int(t0 / dt + 1e-6)
    if table[min(k0, buckets - 1), s_cell[0], s_cell[1]]:
        raise NoPathFound("a moving obstacle is at the start when the path begins")
    parent: dict[tuple[int, int, int], tuple[int, int, int] | None] = {(k0, *s_cell): None}
    arrival = {(k0, *s_cell): t0}
    # among equally early arrivals the one that drives least first: a wait beats a dawdling loop
    heap = [(t0 + h_s[s_cell], 0.0, t0, k0, *s_cell)]
    steps = [(dy, dx, math.hypot(dy, dx) * dt) for dy, dx in _MOVES] + ([(0, 0, dt)] if wait else [])
    expanded = 0
    while heap:
        _, moved, t, k, j, i = heapq.heappop(heap)
        if closed[k, j, i]:
            continue
        closed[k, j, i] = True
        expanded += 1
        if (j, i) == g_cell and not table[k: k + stay + 1, j, i].any():
            out, state = [], (k, j, i)
            while state is not None:
                out.append(state)
                state = parent[state]
            out.reverse()
            return [arrival[s] for s in out], [(s[1], s[2]) for s in out], expanded
        back = parent[(k, j, i)]
        for d, (dy, dx, cost) in enumerate(steps):
            if d < len(_MOVES) and not edges[d, j, i]:
                continue
            if back is not None and (dy or dx) and (j + dy, i + dx) == back[1:] and back[1:] != (j, i):
                continue  # no U-turn onto the point just left: the follower would skip it
            tn = t + cost
            kn = int(tn / dt + 1e-6)  # a move or wait of one dt always reaches the next bucket
            jn, i_n = j + dy, i + dx
            if kn >= buckets or closed[kn, jn, i_n] or table[kn, jn, i_n] or table[kn, j, i]:
                continue
            key = (kn, jn, i_n)
            if key not in arrival or tn < arrival[key]:
                arrival[key], parent[key] = tn, (k, j, i)
                heapq.heappush(heap, (tn + h_s[jn, i_n], moved + (cost if dy or dx else 0.0), tn, kn, jn, i_n))
    raise NoPathFound("no path avoids the moving obstacles within the planning horizon "
                      f"({buckets} time steps of {dt:.3f} s)")


def movers_table(space: ConfigSpace, params: dict[str, Any], horizon_s: float,
                 obstacles: Sequence[MovingObstacle] = (), others: Sequence[TimedPath] = (),
                 obstacle_time_s: float = 0.0) -> np.ndarray:
    """The conflict table of ``obstacles`` (from their time ``obstacle_time_s``, s) and ``others`` on
    ``space``'s lattice over ``horizon_s`` (s), in buckets of ``cell / speed`` s, inflated and widened as
    :class:`SpaceTimeAStar`'s parameters say."""
    cell, dt = float(params["cell"]), float(params["cell"]) / float(params["speed"])
    buckets = min(int(math.ceil(horizon_s / dt)) + 1, MAX_BUCKETS)
    free, _ = _lattice(space, cell)
    if buckets * free.size > MAX_STATES:
        raise PlanTooLarge(
            f"the space-time search would hold {buckets * free.size:.3g} states ({free.shape[1]} x {free.shape[0]} "
            f"lattice points x {buckets} time steps of {dt:.3g} s over {horizon_s:.0f} s); the testbed plans at most "
            f"{MAX_STATES:.3g}: choose a larger `cell` or a shorter `horizon_s`")
    centres, radii = mover_positions(obstacles, others, np.arange(buckets * SAMPLES_PER_BUCKET + 1)
                                     * (dt / SAMPLES_PER_BUCKET), obstacle_time_s)
    inflate = space.radius + cell * math.sqrt(0.5) + float(params["clearance"])
    return conflict_table(centres, radii, free.shape, cell, buckets, inflate,
                          int(math.ceil(float(params["time_margin_s"]) / dt)))


def plan_timed(space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any],
               others: Sequence[TimedPath] = (), table: np.ndarray | None = None,
               obstacle_time_s: float = 0.0) -> tuple[TimedPath, dict[str, Any]]:
    """The earliest path from ``start`` to ``goal`` (m) avoiding the environment's moving obstacles and the
    ``others`` (timed paths: other robots), under :class:`SpaceTimeAStar`'s parameters; its points ``(N, 2)``
    with their times (a wait repeats a point) as a :class:`TimedPath` of the robot's radius, and an info dict.

    ``table``: a conflict table already built for this lattice and buckets of ``cell / speed`` s
    (:func:`movers_table`); then ``others`` and the environment's moving obstacles are in it already.
    ``obstacle_time_s`` (s): the path starts at that obstacle time (a robot replanning mid-run); the
    path's own times still count from 0."""
    cell, speed = float(params["cell"]), float(params["speed"])
    free, edges = _lattice(space, cell)
    s_cell, g_cell = _attach(space, start, free, cell), _attach(space, goal, free, cell)
    graph, ids = grid_graph(free, cell)  # static heuristic: lattice distance to the goal
    dist = dijkstra(graph, directed=False, indices=int(ids[g_cell]))
    h = np.full(free.shape, np.inf)
    h[free] = dist
    if not math.isfinite(h[s_cell]):
        raise NoPathFound("the goal cannot be reached from the start on the space-time lattice")
    dt = cell / speed  # one straight move per bucket
    t0 = math.hypot(*(np.array([s_cell[1], s_cell[0]]) * cell - start)) / speed
    obstacles = space.env.moving_obstacles
    if table is None:
        latest = max([o.delay_s - obstacle_time_s for o in obstacles] + [float(o.times[-1]) for o in others] + [0.0])
        horizon = float(params["horizon_s"]) or 3.0 * (h[s_cell] / speed + t0) + params["arrive_s"] + 20.0 + latest
        table = movers_table(space, params, horizon, obstacles, others, obstacle_time_s)
    buckets = len(table)
    stay = int(math.ceil(float(params["arrive_s"]) / dt))
    times, cells, expanded = _search(table, edges, h / speed, s_cell, g_cell, t0, dt, stay, bool(params["wait"]))
    pts = np.array([[i * cell, j * cell] for j, i in cells])
    t_goal = times[-1] + math.hypot(*(pts[-1] - goal)) / speed
    points = np.vstack([start, pts, goal])
    all_times = np.array([0.0, *times, t_goal])
    # the exact start and goal replace lattice points that coincide with them
    keep = np.ones(len(points), dtype=bool)
    keep[1] = np.hypot(*(points[1] - start)) > 1e-9
    keep[-2] = keep[-2] and np.hypot(*(points[-2] - goal)) > 1e-9
    info = {"speed_m_s": speed, "waits": sum(a == b for a, b in zip(cells[:-1], cells[1:])),
            "expanded": expanded, "time_buckets": buckets, "moving_obstacles": len(obstacles)}
    return TimedPath(points[keep], all_times[keep], space.radius), info
