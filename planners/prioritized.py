"""Prioritized planning for several robots in space-time, the pure planner.

docs/planners.md, "Several robots: prioritized planning", has the overview.

Robots are planned one after the other, in the order given (robot 0 first,
the highest priority), each with the space-time A* of :mod:`planners.st_astar`
(waits allowed: these plans are for robots that can be timed, see
docs/planners.md): every robot avoids the environment's moving obstacles and
the robots planned before it, which follow their timed paths and then stand
at their goals for good.  A robot's goal must stay clear of the robots
planned before it for the rest of the horizon, since it stands there after
arriving.  The conflict table of the robots planned so far grows by one
robot at a time (vectorised, :func:`planners.st_astar.movers_table`).

Like every prioritized planner it is incomplete: a robot may find no path
around the ones that go before it (:class:`~planners.errors.NoPathFound`
names it), where another order would have worked.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from contract.parameters import Param, check_values, defaults_of

from .api import DEFAULT_ROBOT_RADIUS, check_query
from .environment import Environment, load_environment
from .errors import NoPathFound, PlanningError
from .st_astar import SpaceTimeAStar, TimedPath, movers_table, plan_timed

__all__ = ["DESCRIPTION", "EXECUTION_PARAM", "MultiPlan", "check_fleet_params", "fleet_defaults", "fleet_parameters",
           "fleet_waypoints", "min_separation", "plan_prioritized", "timed_waypoints"]

#: the space-time defaults for fleets: waits allowed, a smaller time margin (robots that can be timed)
FLEET_DEFAULTS = {"wait": True, "time_margin_s": 0.5, "clearance": 0.0}
#: how the robots keep to a prioritized plan (a job's ``planner_params.execution``, not the planner's):
#: ``dependencies`` (in the plan's order of passing each shared place) or ``timed`` (by the clock alone)
EXECUTIONS = ("dependencies", "timed")
#: what the testbed's planner list says of ``prioritized`` (a multi-robot job's planner, not a registry one)
DESCRIPTION = ("plans the robots of a multi-robot job together, one after the other: timed paths in which a robot "
               "waits for the ones planned before it (robot 0 first), and the testbed holds it there; any other "
               "planner plans each robot alone (the uncoordinated baseline)")


#: ``execution`` as the listings show it (checked by the server, which keeps to the plan: its values are a choice)
EXECUTION_PARAM = Param("execution", default=EXECUTIONS[0], type="string",
                        doc=f"how the robots keep to the plan: {' or '.join(EXECUTIONS)} (in its order of passing, "
                            "or by the clock)")


def fleet_parameters() -> tuple[Param, ...]:
    """The planner's own parameters: the space-time planner's, with :data:`FLEET_DEFAULTS` as their defaults."""
    return tuple(dataclasses.replace(p, default=FLEET_DEFAULTS.get(p.name, p.default))
                 for p in SpaceTimeAStar.parameters or ())


def check_fleet_params(params: Mapping[str, Any] | None) -> dict[str, Any]:
    """``params`` over :func:`fleet_parameters`' defaults, each checked; ``ValueError`` naming a bad one."""
    return check_values(fleet_parameters(), params, owner="planner 'prioritized'", label="parameter prioritized.")


def fleet_defaults() -> dict[str, Any]:
    """Every parameter a multi-robot job's ``planner_params`` may give ``prioritized``, with its default: the
    space-time planner's, :data:`FLEET_DEFAULTS` over them, and ``execution``."""
    return {**(defaults_of(fleet_parameters()) or {}), "execution": EXECUTIONS[0]}


@dataclass
class MultiPlan:
    """Timed ``paths`` (one :class:`TimedPath` per robot, in the robots' order; m, s), ``makespan_s`` (s, the
    last arrival), ``planning_time_s`` (s) and per-robot ``info``."""

    paths: list[TimedPath]
    makespan_s: float
    planning_time_s: float
    info: list[dict[str, Any]] = field(default_factory=list)
    #: the centre distance (m) under which the planner kept two robots' lattice points apart in time: two
    #: radii with the planning margin, half a lattice diagonal and the clearance
    conflict_m: float = 0.0


def min_separation(paths: Sequence[TimedPath], dt: float = 0.05) -> float:
    """The smallest centre distance (m) between any two of ``paths``, sampled every ``dt`` (s) until the last
    arrival (robots stand at their goals afterwards); ``inf`` for fewer than two."""
    if len(paths) < 2:
        return math.inf
    end = max(float(p.times[-1]) for p in paths)
    t = np.arange(0.0, end + dt, dt)
    xy = np.stack([p.position(t) for p in paths])  # (R, T, 2)
    d = np.hypot(xy[:, None, :, 0] - xy[None, :, :, 0], xy[:, None, :, 1] - xy[None, :, :, 1])  # (R, R, T)
    d[np.arange(len(paths)), np.arange(len(paths))] = np.inf
    return float(d.min())


def _poses(env: Environment, points: Sequence[Sequence[float]], what: str) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) < 1:
        raise PlanningError(f"{what} must be a list of [x, y] poses, got shape {p.shape}")
    return p[:, :2]


def plan_prioritized(env: Environment | str, starts: Sequence[Sequence[float]], goals: Sequence[Sequence[float]], *,
                     robot_radius: float = DEFAULT_ROBOT_RADIUS, planning_margin: float = 0.0,
                     resolution: float = 0.01, params: Mapping[str, Any] | None = None) -> MultiPlan:
    """Timed paths for robots from ``starts`` to ``goals`` (``(R, 2+)``, m) that keep ``robot_radius +
    planning_margin`` (m) from the blocks, the moving obstacles and each other (centre distance at least
    twice that, plus the lattice's inflation), robot 0 first.  ``params``: :class:`SpaceTimeAStar`'s, with
    :data:`FLEET_DEFAULTS`.  Raises :class:`PlanningError` (a start or goal not free, two robots sharing one)
    or :class:`NoPathFound` naming the robot that found no way."""
    env = load_environment(env)
    t_begin = time.perf_counter()
    s_xy, g_xy = _poses(env, starts, "starts"), _poses(env, goals, "goals")
    if len(s_xy) != len(g_xy):
        raise PlanningError(f"{len(s_xy)} starts but {len(g_xy)} goals")
    checked = check_fleet_params(params)
    radius = robot_radius + planning_margin
    for what, pts in (("start", s_xy), ("goal", g_xy)):
        d = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
        d[np.diag_indices(len(pts))] = np.inf
        if len(pts) > 1 and d.min() < 2 * radius:
            a, b = np.unravel_index(int(np.argmin(d)), d.shape)
            raise PlanningError(f"robots {a} and {b} have {what}s {d[a, b]:.3f} m apart, closer than two robot "
                                f"radii with the planning margin ({2 * radius:.3f} m)")
    spaces = [check_query(env, s, g, robot_radius=robot_radius, resolution=resolution,
                          planning_margin=planning_margin)[0] for s, g in zip(s_xy, g_xy)]
    space = spaces[0]
    speed = float(checked["speed"])
    span = float(np.hypot(*(g_xy - s_xy).T).max()) + env.width + env.height  # generous: detours and waits
    horizon = float(checked["horizon_s"]) or (3.0 * span / speed + 20.0 + max(
        [o.delay_s for o in env.moving_obstacles] + [0.0]))
    run = {**checked, "horizon_s": horizon, "arrive_s": horizon}  # a robot stands at its goal for good
    table = movers_table(space, run, horizon, env.moving_obstacles)
    paths, infos = [], []
    for r, (s, g) in enumerate(zip(s_xy, g_xy)):
        try:
            timed, info = plan_timed(space, s, g, run, table=table)
        except NoPathFound as exc:
            raise NoPathFound(f"robot {r} (of {len(s_xy)}, planned in order): {exc}") from None
        paths.append(timed)
        infos.append(info)
        if r + 1 < len(s_xy):
            table |= movers_table(space, run, horizon, others=[timed])
    conflict = 2 * space.radius + float(run["cell"]) * math.sqrt(0.5) + float(run["clearance"])
    return MultiPlan(paths, max(float(p.times[-1]) for p in paths), time.perf_counter() - t_begin, infos, conflict)


def timed_waypoints(timed: TimedPath, goal_heading: float | None = None,
                    dense: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A timed path as waypoints ``(K, 3)`` (m, m, rad; each facing the next, the last ``goal_heading`` or the
    last segment's direction) with the plan's arrival and departure times ``(K,)`` (s) at each; the last
    point's departure is ``inf`` (the robot stands at its goal for good).

    The waypoints are the plan's corners and waits (straight runs of lattice moves merged) or, ``dense``,
    every distinct lattice point (one waypoint per move: what execution by dependencies needs,
    :func:`planners.dependencies.fleet_dependencies`)."""
    pts, t = np.asarray(timed.points, dtype=float), np.asarray(timed.times, dtype=float)
    same = np.r_[False, (np.diff(pts, axis=0) == 0).all(axis=1)]  # point k repeats point k - 1
    keep = ~same
    xy = pts[keep]
    leave = np.maximum.reduceat(t, np.flatnonzero(keep))  # the last time at each distinct point
    arrive = t[keep]
    waits = leave > arrive + 1e-9
    seg = np.diff(xy, axis=0)
    turn = np.r_[True, np.abs(seg[1:, 0] * seg[:-1, 1] - seg[1:, 1] * seg[:-1, 0]) > 1e-12, True] if len(xy) > 1 \
        else np.array([True])
    corner = turn | waits | dense
    corner[0] = corner[-1] = True
    xy, arrive, leave = xy[corner], arrive[corner], leave[corner]
    leave[-1] = np.inf
    d = np.diff(xy, axis=0)
    head = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    last = goal_heading if goal_heading is not None else (float(head[-1]) if len(head) else 0.0)
    return np.column_stack([xy, np.r_[head, last]]), arrive, leave


def fleet_waypoints(timed: TimedPath, goal_heading: float | None = None,
                    dense: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A timed path as a follower's path and its holds: waypoints ``(K, 3)`` (m, m, rad; each facing the next,
    the last ``goal_heading`` or the last segment's direction) at the plan's corners and waits (``dense``: at
    every lattice point, :func:`timed_waypoints`), and departure times ``(K,)`` (s): where the plan waits,
    the time it leaves the point, NaN elsewhere.

    Straight runs of lattice moves become one segment; a wait (a repeated point) becomes one waypoint the
    robot holds at (:func:`robot_agent.engine.fleet.simulate_fleet`)."""
    wps, arrive, leave = timed_waypoints(timed, goal_heading, dense)
    depart = np.where(leave > arrive + 1e-9, leave, np.nan)
    depart[-1] = np.nan
    return wps, depart
