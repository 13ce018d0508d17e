"""LaCAM* for the testbed's fleets: a complete multi-robot planner on a grid of robot-sized cells.

docs/planners.md, "Several robots: LaCAM", has the overview.  The search itself (LaCAM* with PIBT as
its configuration generator) is compiled, in :mod:`planners._lacam_kernel`, and imported only when a
plan is made: this module (the planner's parameters and description) loads without numba, as the
server needs.

**The grid.**  Robots plan on a lattice of points every ``cell`` metres (``(i cell, j cell)``, as
``st_astar``'s), 4-connected, a point free when the robot (radius with the planning margin) fits there
and a move free when its segment is free.  A cell is at least the robot's footprint: ``cell`` must
exceed two robot radii with the margin (0.13 m for a BeBot; the default is 0.15 m), so two robots on
different lattice points, standing or moving along lattice edges that share no point, are at least one
cell apart -- the plan needs no geometry beyond "one robot per point", which is what MAPF solvers
(LaCAM, PIBT) plan for.  A finer grid with footprint-aware conflicts would follow the blocks more
closely but makes every robot a multi-cell agent, which PIBT's one-agent-per-vertex pushes do not
model; the coarse grid keeps LaCAM's completeness and speed and costs at most half a cell of detour.

**Off the grid.**  A job's starts and goals are anywhere (two robots at least two radii apart).  Each
robot is given its own start point and goal point of the lattice (an assignment that minimises the
squared distances, avoiding points next to another robot's start), drives there first and from there
last, in *rounds*: a robot moves to (from) its point only when its segment keeps the conflict distance
from every robot that stands still meanwhile and from every robot moving in the same round.

**The plan** is then LaCAM* between the two configurations; robots that must not rotate (each moving
into the point the next one leaves, round a cycle) are kept from it, since the testbed executes the
plan by its order of passage (:mod:`planners.dependencies`: a robot enters a point only once the robot
before it there has reached its next point; a rotation would wait for itself).  Following is allowed.
:func:`lacam_schedule` turns the plan into the waypoints and the dependency tables the fleet executes,
adding to :func:`~planners.dependencies.fleet_dependencies` (points closer than the conflict distance)
the orders the approach and the final moves need (segments closer than it), and checks that the
order of passage can always be completed (it has no cycle).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Mapping, Sequence

import numpy as np

from contract.parameters import Param, check_values, defaults_of

from .api import DEFAULT_ROBOT_RADIUS, check_query
from .environment import Environment, load_environment
from .errors import NoPathFound, PlanningError
from .grid import ConfigSpace
from .prioritized import MultiPlan, timed_waypoints
from .st_astar import TimedPath

__all__ = ["DESCRIPTION", "GridPlan", "LacamPlan", "Lattice", "check_lacam_params", "lacam_defaults",
           "lacam_parameters", "lacam_schedule", "lattice", "plan_grid", "plan_lacam", "segment_distances"]

NAME = "lacam"
#: what the testbed's planner list says of ``lacam``
DESCRIPTION = ("plans the robots of a multi-robot job together with LaCAM* (PIBT as its configuration generator) "
               "on a grid of robot-sized cells: complete where prioritized planning gives up, an anytime "
               "budget; executed in the plan's order of passage")

PARAMETERS = (
    Param("cell", "m", 0.15, 0.05, 0.5, "spacing of the grid the robots plan on; more than two robot radii with "
          "the planning margin"),
    Param("speed", "m/s", 0.18, 0.0, 1.0, "the speed the plan's timing assumes (one cell per step)",
          low_exclusive=True),
    Param("time_limit_s", "s", 5.0, 0.0, 60.0, "the anytime budget: the search stops then, with the best plan so "
          "far or none", low_exclusive=True),
    Param("refine", "iterations", 2000, 0, 10_000_000, "LaCAM* iterations spent improving the first plan's sum "
          "of costs (0: the first plan)", type="integer"),
    Param("swap", default=True, type="boolean", doc="PIBT's swap operation (two robots passing each other in a "
          "corridor)"),
)


def lacam_parameters() -> tuple[Param, ...]:
    """The planner's parameters (name, unit, default, range)."""
    return PARAMETERS


def check_lacam_params(params: Mapping[str, Any] | None) -> dict[str, Any]:
    """``params`` over the defaults, each checked; ``ValueError`` naming a bad one."""
    return check_values(PARAMETERS, params, owner=f"planner '{NAME}'", label=f"parameter {NAME}.")


def lacam_defaults() -> dict[str, Any]:
    """Every parameter a multi-robot job's ``planner_params`` may give ``lacam``, with its default."""
    return dict(defaults_of(PARAMETERS) or {})


# -- the lattice ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Lattice:
    """Free points ``xy`` ``(V, 2)`` (m) of a grid of spacing ``cell`` (m), their grid indices ``ij`` ``(V, 2)``
    (column, row), neighbour table ``nbr`` ``(V, 4)`` (-1: none) and counts ``deg`` ``(V,)``; ``index``
    ``(ny, nx)`` maps grid indices to point ids (-1: not free)."""

    cell: float
    xy: np.ndarray
    ij: np.ndarray
    nbr: np.ndarray
    deg: np.ndarray
    index: np.ndarray


def _neighbours(free: np.ndarray, edge_ok: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point ids ``(ny, nx)`` of the ``free`` grid and its 4-neighbour table and counts; ``edge_ok`` ``(4, ny, nx)``
    says which moves (+x, -x, +y, -y) are allowed (all between free points when None)."""
    ny, nx = free.shape
    index = np.full(free.shape, -1, dtype=np.int64)
    rows, cols = np.nonzero(free)
    index[rows, cols] = np.arange(len(rows))
    nbr = np.full((len(rows), 4), -1, dtype=np.int32)
    deg = np.zeros(len(rows), dtype=np.int32)
    for d, (dx, dy) in enumerate(((1, 0), (-1, 0), (0, 1), (0, -1))):
        c, r = cols + dx, rows + dy
        inside = (c >= 0) & (c < nx) & (r >= 0) & (r < ny)
        ok = np.zeros(len(rows), dtype=bool)
        ok[inside] = free[r[inside], c[inside]]
        if edge_ok is not None:
            ok &= edge_ok[d, rows, cols]
        v = np.flatnonzero(ok)
        nbr[v, deg[v]] = index[r[v], c[v]]
        deg[v] += 1
    return index, nbr, deg


@lru_cache(maxsize=8)
def lattice(space: ConfigSpace, cell: float) -> Lattice:
    """The free points and moves of the grid of spacing ``cell`` (m) in ``space`` (cached)."""
    env = space.env
    nx, ny = int(math.floor(env.width / cell + 1e-9)) + 1, int(math.floor(env.height / cell + 1e-9)) + 1
    jj, ii = np.mgrid[0:ny, 0:nx]
    pts = np.column_stack([ii.ravel() * cell, jj.ravel() * cell])
    free = space.is_free(pts).reshape(ny, nx)
    edge_ok = np.zeros((4, ny, nx), dtype=bool)
    for d, (dx, dy) in enumerate(((1, 0), (-1, 0), (0, 1), (0, -1))):
        ti, tj = ii + dx, jj + dy
        ok = free & (ti >= 0) & (ti < nx) & (tj >= 0) & (tj < ny)
        ok[ok] &= free[tj[ok], ti[ok]]
        src = np.flatnonzero(ok.ravel())
        dst = np.column_stack([ti.ravel()[src] * cell, tj.ravel()[src] * cell])
        ok.ravel()[src] = space.segments_free(pts[src], dst)
        edge_ok[d] = ok
    index, nbr, deg = _neighbours(free, edge_ok)
    rows, cols = np.nonzero(free)
    return Lattice(cell, np.column_stack([cols * cell, rows * cell]).astype(float),
                   np.column_stack([cols, rows]), nbr, deg, index)


# -- the search on a graph --------------------------------------------------------------------------------

@dataclass
class GridPlan:
    """LaCAM*'s answer on a graph: ``configs`` ``(T + 1, n)`` vertex ids from the starts to the goals (empty
    when none was found), ``status`` (``solved``, ``unsolvable``: proven to have no solution, ``budget``: none
    found within it), ``time_s`` (s) and the search's ``stats``."""

    configs: np.ndarray
    status: str
    time_s: float
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def solved(self) -> bool:
        return self.status == "solved"

    @property
    def makespan(self) -> int:
        """Steps until the last agent is at its goal for good."""
        return int(len(self.configs) - 1) if len(self.configs) else -1

    @property
    def sum_of_costs(self) -> int:
        """Sum over agents of the step after which each stays at its goal for good."""
        if not len(self.configs):
            return -1
        away = self.configs != self.configs[-1]
        last = np.where(away.any(axis=0), len(away) - np.argmax(away[::-1], axis=0), 0)
        return int(last.sum())


def plan_grid(nbr: np.ndarray, deg: np.ndarray, starts: Sequence[int], goals: Sequence[int], *, seed: int = 0,
              time_limit_s: float = 5.0, refine: int = 0, swap: bool = True, rotations: bool = False,
              max_iterations: int = 0) -> GridPlan:
    """LaCAM* on the graph ``nbr``/``deg`` (:class:`Lattice`'s, or a map's: :func:`planners.movingai.grid_graph`)
    from vertex ids ``starts`` to ``goals``; ``rotations``: whether agents may move round a cycle (the usual MAPF
    model; the testbed's plans forbid it).  Raises ``ValueError`` for bad input (repeated vertices)."""
    from . import _lacam_kernel as kernel

    s = np.asarray(starts, dtype=np.int32)
    g = np.asarray(goals, dtype=np.int32)
    if len(s) != len(g):
        raise ValueError(f"{len(s)} starts but {len(g)} goals")
    for what, v in (("start", s), ("goal", g)):
        if len(np.unique(v)) != len(v):
            raise ValueError(f"two agents share a {what} vertex")
    nbr = np.ascontiguousarray(nbr, dtype=np.int32)
    deg = np.ascontiguousarray(deg, dtype=np.int32)
    t0 = time.perf_counter()
    dist = kernel.bfs_distances(nbr, deg, g)
    cut = np.flatnonzero(dist[np.arange(len(s)), s] >= kernel._INF)
    if len(cut):
        return GridPlan(np.zeros((0, len(s)), dtype=np.int32), "unsolvable", time.perf_counter() - t0,
                        {"unreachable": cut.tolist()})
    status, configs, st = kernel.lacam(nbr, deg, s, g, dist, int(seed) & 0x7FFFFFFF, float(time_limit_s),
                                       int(max_iterations), int(refine), bool(swap), bool(rotations))
    names = {kernel.SOLVED: "solved", kernel.UNSOLVABLE: "unsolvable", kernel.BUDGET: "budget"}
    stats = {"iterations": int(st[0]), "nodes": int(st[1]), "constraint_nodes": int(st[2]),
             "first_solution_iteration": int(st[3]), "first_solution_cost": int(st[4]), "optimal": bool(st[5])}
    plan = GridPlan(configs, names[int(status)], time.perf_counter() - t0, stats)
    if plan.solved:
        stats["cost"] = int(_sum_of_loss(configs, g))
        stats["lower_bound"] = int(dist[np.arange(len(s)), s].sum())
    return plan


def _sum_of_loss(configs: np.ndarray, goals: np.ndarray) -> int:
    """Steps agents spend off their goal, or leaving or entering it (LaCAM*'s cost)."""
    at = configs == goals[None, :]
    return int((~(at[:-1] & at[1:])).sum())


# -- the testbed's fleets ---------------------------------------------------------------------------------

@dataclass
class LacamPlan(MultiPlan):
    """A :class:`~planners.prioritized.MultiPlan` of LaCAM*: besides the timed paths, per robot whether it
    approaches its start point (``approach``) and leaves its goal point (``leave``) off the grid, and the
    round of each (-1: none); ``cell`` (m); ``grid`` the search's :class:`GridPlan` (its statistics)."""

    approach: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    leave: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    approach_round: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    leave_round: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    cell: float = 0.0
    grid: GridPlan | None = None


def segment_distances(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """The smallest distance (m) between segments ``a0 a1`` and ``b0 b1`` (arrays ``(..., 2)``, broadcast)."""
    a0, a1, b0, b1 = (np.asarray(x, dtype=float) for x in (a0, a1, b0, b1))

    def point_seg(p: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        d = q1 - q0
        dd = (d * d).sum(-1)
        t = np.clip(np.where(dd > 0, ((p - q0) * d).sum(-1) / np.where(dd > 0, dd, 1.0), 0.0), 0.0, 1.0)
        return np.hypot(*np.moveaxis(q0 + t[..., None] * d - p, -1, 0))

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    da, db = a1 - a0, b1 - b0
    s1, s2 = cross(da, b0 - a0), cross(da, b1 - a0)
    s3, s4 = cross(db, a0 - b0), cross(db, a1 - b0)
    crossing = (s1 * s2 < 0) & (s3 * s4 < 0)
    best = np.minimum(np.minimum(point_seg(a0, b0, b1), point_seg(a1, b0, b1)),
                      np.minimum(point_seg(b0, a0, a1), point_seg(b1, a0, a1)))
    return np.where(crossing, 0.0, best)


def _assign(points: np.ndarray, lat: Lattice, space: ConfigSpace, others: np.ndarray, conflict: float,
            what: str) -> np.ndarray:
    """Distinct lattice point ids for ``points`` ``(n, 2)`` (m): within two cells, reached by a free segment,
    the squared distances smallest, points closer than ``conflict`` (m) to one of ``others`` (the other robots'
    poses) avoided where possible."""
    from scipy.optimize import linear_sum_assignment

    n, cell = len(points), lat.cell
    reach = 2.0 * cell * math.sqrt(2.0) + 1e-9
    near_sets = []
    for p in points:
        c = np.flatnonzero(np.hypot(*(lat.xy - p).T) <= reach)
        if len(c):
            c = c[space.segments_free(np.repeat(p[None], len(c), axis=0), lat.xy[c])]
        near_sets.append(c)
    cols = np.unique(np.concatenate(near_sets)) if n else np.zeros(0, dtype=int)
    big = 1e9
    cost = np.full((n, len(cols)), big)
    pos = {int(c): k for k, c in enumerate(cols)}
    for i, c in enumerate(near_sets):
        if not len(c):
            raise PlanningError(f"robot {i}'s {what} ({points[i, 0]:.3f}, {points[i, 1]:.3f}) has no free point of the "
                                f"{cell:g} m grid within {reach:.3f} m")
        d2 = ((lat.xy[c] - points[i]) ** 2).sum(1)
        others_i = np.delete(others, i, axis=0)
        crowd = (np.hypot(*(lat.xy[c][:, None] - others_i[None]).transpose(2, 0, 1)) < conflict).sum(1) \
            if len(others_i) else 0
        cost[i, [pos[int(x)] for x in c]] = d2 + 4 * cell * cell * crowd
    rows, picked = linear_sum_assignment(cost)
    if (cost[rows, picked] >= big).any():
        i = int(rows[np.argmax(cost[rows, picked] >= big)])
        raise PlanningError(f"the {what}s of the robots crowd the {cell:g} m grid: robot {i} finds no grid point of "
                            "its own near its " + what)
    out = np.empty(n, dtype=np.int64)
    out[rows] = cols[picked]
    return out


def _rounds(src: np.ndarray, dst: np.ndarray, moves: np.ndarray, conflict: float, what: str) -> np.ndarray:
    """The round (0, 1, ...) in which each robot that ``moves`` drives from ``src`` to ``dst`` (m), the others
    standing at ``src`` (-1 for a robot that does not move): a robot moves when its segment keeps ``conflict``
    (m) from every other robot where it is and from the segments of those moving in the same round."""
    n = len(src)
    pos = src.copy()
    rnd = np.full(n, -1, dtype=int)
    todo = [i for i in range(n) if moves[i]]
    r = 0
    while todo:
        chosen: list[int] = []
        for i in todo:
            others = np.array([k for k in range(n) if k != i and k not in chosen], dtype=int)
            ok = True
            if len(others):
                ok = bool((segment_distances(src[i], dst[i], pos[others], pos[others]) >= conflict).all())
            if ok and chosen:
                c = np.array(chosen)
                ok = bool((segment_distances(src[i], dst[i], src[c], dst[c]) >= conflict).all())
            if ok:
                chosen.append(i)
        if not chosen:
            raise PlanningError(f"robots {', '.join(map(str, todo))} cannot reach their {what} points of the grid "
                                f"without coming closer than {conflict:.3f} m to another robot")
        for i in chosen:
            pos[i] = dst[i]
            rnd[i] = r
        todo = [i for i in todo if i not in chosen]
        r += 1
    return rnd


def _poses(points: Sequence[Sequence[float]], what: str) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) < 1:
        raise PlanningError(f"{what} must be a list of [x, y] poses, got shape {p.shape}")
    return p[:, :2].copy()


def plan_lacam(env: Environment | str, starts: Sequence[Sequence[float]], goals: Sequence[Sequence[float]], *,
               robot_radius: float = DEFAULT_ROBOT_RADIUS, planning_margin: float = 0.0, resolution: float = 0.01,
               params: Mapping[str, Any] | None = None, seed: int = 0) -> LacamPlan:
    """Timed paths for robots from ``starts`` to ``goals`` (``(R, 2+)``, m) on the grid of ``params["cell"]``
    (:data:`PARAMETERS`) in ``env``, keeping ``robot_radius + planning_margin`` (m) from the blocks; the same
    ``seed`` gives the same plan (unless the time budget cuts the search).  Each step of the plan is one cell
    at ``speed``.  Raises :class:`PlanningError` (bad fleets, moving obstacles, a start or goal the grid
    cannot serve) or :class:`NoPathFound` (the grid connects no way, or none was found within the budget)."""
    env = load_environment(env)
    t_begin = time.perf_counter()
    checked = check_lacam_params(params)
    if env.moving_obstacles:
        raise PlanningError(f"{NAME} plans among the blocks only; this environment has {len(env.moving_obstacles)} "
                            "moving obstacle(s): plan with prioritized, which avoids them")
    s_xy, g_xy = _poses(starts, "starts"), _poses(goals, "goals")
    n = len(s_xy)
    if len(g_xy) != n:
        raise PlanningError(f"{n} starts but {len(g_xy)} goals")
    radius = robot_radius + planning_margin
    conflict = 2 * radius
    cell = float(checked["cell"])
    if cell <= conflict:
        raise PlanningError(f"parameter {NAME}.cell must exceed two robot radii with the planning margin "
                            f"({conflict:.3f} m), got {cell:g}")
    for what, pts in (("start", s_xy), ("goal", g_xy)):
        d = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
        d[np.diag_indices(n)] = np.inf
        if n > 1 and d.min() < conflict:
            a, b = np.unravel_index(int(np.argmin(d)), d.shape)
            raise PlanningError(f"robots {a} and {b} have {what}s {d[a, b]:.3f} m apart, closer than two robot "
                                f"radii with the planning margin ({conflict:.3f} m)")
    space = None
    for s, g in zip(s_xy, g_xy):
        space = check_query(env, s, g, robot_radius=robot_radius, resolution=resolution,
                            planning_margin=planning_margin)[0]
    assert space is not None
    lat = lattice(space, cell)
    c_s = _assign(s_xy, lat, space, s_xy, conflict, "start")
    c_g = _assign(g_xy, lat, space, g_xy, conflict, "goal")
    approach = np.hypot(*(lat.xy[c_s] - s_xy).T) > 1e-9
    leave = np.hypot(*(lat.xy[c_g] - g_xy).T) > 1e-9
    a_round = _rounds(s_xy, lat.xy[c_s], approach, conflict, "start")
    l_round = _rounds(g_xy, lat.xy[c_g], leave, conflict, "goal")  # in reverse: from the goals back
    grid = plan_grid(lat.nbr, lat.deg, c_s, c_g, seed=seed, time_limit_s=float(checked["time_limit_s"]),
                     refine=int(checked["refine"]), swap=bool(checked["swap"]), rotations=False)
    if not grid.solved:
        if grid.status == "unsolvable":
            cut = grid.stats.get("unreachable")
            if cut:
                raise NoPathFound(f"robot {cut[0]}'s goal cannot be reached from its start on the {cell:g} m grid "
                                  "(a smaller cell may pass where this one does not)")
            raise NoPathFound(f"no plan exists on the {cell:g} m grid: every configuration reachable from the starts "
                              f"was explored ({grid.stats['nodes']} of them)")
        raise NoPathFound(f"no plan found within the budget of {checked['time_limit_s']:g} s "
                          f"({grid.stats['iterations']} iterations)")
    ra = int(a_round.max()) + 1 if approach.any() else 0
    rl = int(l_round.max()) + 1 if leave.any() else 0
    cfg = grid.configs
    steps = ra + (len(cfg) - 1) + rl
    tau = cell / float(checked["speed"])
    paths, infos = [], []
    for i in range(n):
        pts = np.empty((steps + 1, 2))
        # the approach: at the start until its round, at its grid point after
        pts[: ra + 1] = lat.xy[c_s[i]]
        if approach[i]:
            pts[: a_round[i] + 1] = s_xy[i]
        pts[ra: ra + len(cfg)] = lat.xy[cfg[:, i]]
        pts[ra + len(cfg) - 1:] = lat.xy[c_g[i]]
        if leave[i]:  # rounds in reverse order: the last round found leaves first
            first = ra + len(cfg) - 1 + (rl - 1 - l_round[i]) + 1
            pts[first:] = g_xy[i]
        times = np.arange(steps + 1) * tau
        # exact ends
        moved = np.r_[True, (np.diff(pts, axis=0) != 0).any(axis=1)]
        paths.append(TimedPath(pts, times, radius))
        infos.append({"moves": int(moved[1:].sum()), "waits": int((~moved[1:]).sum()),
                      "approach_round": int(a_round[i]), "leave_round": int(rl - 1 - l_round[i]) if leave[i] else -1})
    arrival = [float(p.times[np.flatnonzero((np.diff(p.points, axis=0) != 0).any(axis=1))[-1] + 1])
               if (np.diff(p.points, axis=0) != 0).any() else 0.0 for p in paths]
    plan = LacamPlan(paths, max(arrival + [0.0]), time.perf_counter() - t_begin, infos, conflict,
                     approach=approach, leave=leave, approach_round=a_round,
                     leave_round=np.where(leave, rl - 1 - l_round, -1), cell=cell, grid=grid)
    return plan


def lacam_schedule(plan: LacamPlan, goal_headings: Sequence[float | None] | None = None) -> tuple[
        list[np.ndarray], list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """What a fleet executes of ``plan``: per robot its waypoints ``(K, 3)`` (every grid point it passes, each
    facing the next, the last ``goal_headings[i]``), the plan's arrival and departure times ``(K,)`` (s) and the
    dependency table ``(R, K)`` of :func:`planners.dependencies.fleet_dependencies` (points closer than the
    conflict distance, in the plan's order) with the orders the moves off the grid need: a robot's move onto
    its start point, along the grid or off its goal point waits for every robot whose move off the grid comes
    closer than the conflict distance and goes first in the plan.  Raises :class:`PlanningError` when the
    order of passage could not be completed (a cycle: it never happens for a valid plan)."""
    from .dependencies import fleet_dependencies

    n = len(plan.paths)
    heads = list(goal_headings) if goal_headings is not None else [None] * n
    sched = [timed_waypoints(p, h, dense=True) for p, h in zip(plan.paths, heads)]
    wps = [w for w, _, _ in sched]
    dep = fleet_dependencies(wps, [a for _, a, _ in sched], [lv for _, _, lv in sched], plan.conflict_m)
    size = np.array([len(w) for w in wps])
    d = plan.conflict_m
    xy = [w[:, :2] for w in wps]

    def need(j: int, h: int, k: int, index: int) -> None:
        dep[j][h, k] = max(dep[j][h, k], min(index, size[h] - 1))

    # grid edges of every robot: (robot, index of the edge's end)
    e_rob, e_end = [], []
    for j in range(n):
        lo = 1 if plan.approach[j] else 0
        hi = size[j] - (2 if plan.leave[j] else 1)
        e_rob += [j] * max(0, hi - lo)
        e_end += list(range(lo + 1, hi + 1))
    er, ee = np.array(e_rob, dtype=int), np.array(e_end, dtype=int)
    e0 = np.array([xy[j][m - 1] for j, m in zip(er, ee)]).reshape(-1, 2)
    e1 = np.array([xy[j][m] for j, m in zip(er, ee)]).reshape(-1, 2)
    # the moves off the grid: onto the start point (A) and off the goal point (L); a robot without one has a
    # point far away instead, and is left out by its flag
    far = np.full(2, 1e9)
    a0 = np.array([xy[i][0] if plan.approach[i] else far for i in range(n)])
    a1 = np.array([xy[i][1] if plan.approach[i] else far for i in range(n)])
    b0 = np.array([xy[i][-2] if plan.leave[i] else far for i in range(n)])
    b1 = np.array([xy[i][-1] if plan.leave[i] else far for i in range(n)])
    app, off = plan.approach.astype(bool), plan.leave.astype(bool)
    other = ~np.eye(n, dtype=bool)
    # approaches in the order of their rounds: k waits at its start for i to reach its grid point
    near = (segment_distances(a0[:, None], a1[:, None], a0[None], a1[None]) < d) & other
    near &= app[:, None] & app[None] & (plan.approach_round[:, None] < plan.approach_round[None])
    for i, k in zip(*np.nonzero(near)):
        need(int(k), int(i), 0, 1)
    # grid moves after every approach near them: j leaves waypoint m - 1 once k reached its grid point
    near = (segment_distances(e0[:, None], e1[:, None], a0[None], a1[None]) < d) & app[None]
    near &= er[:, None] != np.arange(n)[None]
    for e, k in zip(*np.nonzero(near)):
        need(int(er[e]), int(k), int(ee[e]) - 1, 1)
    # final moves after every approach near them
    near = (segment_distances(b0[:, None], b1[:, None], a0[None], a1[None]) < d) & other & off[:, None] & app[None]
    for i, k in zip(*np.nonzero(near)):
        need(int(i), int(k), int(size[i]) - 2, 1)
    # the final move after the grid moves near it: k leaves its goal point once j passed
    near = (segment_distances(e0[:, None], e1[:, None], b0[None], b1[None]) < d) & off[None]
    near &= er[:, None] != np.arange(n)[None]
    for e, k in zip(*np.nonzero(near)):
        need(int(k), int(er[e]), int(size[k]) - 2, int(ee[e]))
    # final moves in the order of their rounds
    near = (segment_distances(b0[:, None], b1[:, None], b0[None], b1[None]) < d) & other
    near &= off[:, None] & off[None] & (plan.leave_round[:, None] < plan.leave_round[None])
    for i, k in zip(*np.nonzero(near)):
        need(int(k), int(i), int(size[k]) - 2, int(size[i]) - 1)
    dep = [np.maximum.accumulate(t, axis=1) for t in dep]
    _check_completes(dep, size)
    return wps, [a for _, a, _ in sched], [lv for _, _, lv in sched], dep


def _check_completes(dep: list[np.ndarray], size: np.ndarray) -> None:
    """Raise :class:`PlanningError` unless robots released by ``dep`` (per robot ``(R, K)``) can all reach their
    last waypoints, each leaving a waypoint once the robots it waits for have reached theirs."""
    n = len(dep)
    reached = np.zeros(n, dtype=np.int64)
    last = size - 1
    rows = np.arange(n)
    while True:
        k = np.minimum(reached, last)
        req = np.stack([dep[j][:, k[j]] for j in range(n)])  # (R, R): what robot j waits for to leave k_j
        can = (reached < last) & (reached[None, :] >= req).all(axis=1)
        if not can.any():
            break
        reached[rows[can]] += 1
    if (reached < last).any():
        stuck = np.flatnonzero(reached < last)
        raise PlanningError(f"the plan's order of passage cannot be completed: robots {stuck.tolist()} would wait "
                            "for each other")
