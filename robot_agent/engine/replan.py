"""Replanning while driving: when the path ahead is blocked, a new path to the goal around what moves.

A controller that supports it (regulated pure pursuit, ``replan`` = 1;
:data:`contract.controller_specs.REPLAN_PARAMS`) replans as nav2's
behaviour tree does with its "replan when the path is invalid" pattern, but
with the moving obstacles' trajectories known exactly (the robot's world
holds them, :mod:`planners.moving`):

1. **Check** (:func:`blocked`), every :data:`CHECK_PERIOD_S` of experiment
   time, not every control step: the path ahead of the robot's projection,
   ``replan_horizon_s`` of driving at its ``speed_m_s``, sampled every
   :data:`SAMPLE_M`; a sample is blocked when a moving obstacle comes within
   its radius + the robot's collision radius + :data:`MARGIN_M` of it at any
   time within :data:`TIME_WINDOW_S` of when the robot would be there, or
   when another robot of its world stands within two collision radii +
   :data:`MARGIN_M` of it where it is now.
2. **Replan** (:func:`solve`), at most once per ``replan_min_interval_s``:
   the space-time planner (:func:`planners.st_astar.plan_timed`, its defaults)
   from the robot's believed position, at its obstacles' current time, to the
   path's last point, in the static map the robot was built (its world's
   ``T,T,B`` blocks, in its area) around the moving obstacles and the other
   robots standing where they are; post-processed as the testbed's plans
   (:func:`planners.postprocess.postprocess`, the last point's heading kept).
3. **Follow**: the new path replaces the old one without a stop (same
   speed, same noise stream, same obstacle clock, the timeout extended to the
   new path's); its waypoints are numbered afresh from 0.  Each attempt is a
   ``REPLAN`` event (``EV,REPLAN,<points>,<ms>,<t>``; 0 points: no path was
   found, the robot keeps its path).

The check is cheap numpy and runs where the simulation runs; :func:`solve`
is pure (a :class:`Request` in, a :class:`Result` out) so an agent runs it
in a worker thread, its simulation paused meanwhile (so the run is the same
at every time scale and headless).  Units: m, rad, s.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from contract.controller_specs import Selection
from planners.environment import Block, Environment
from planners.errors import PlanningError
from planners.grid import config_space
from planners.moving import REPEAT_MODES, MovingObstacle, positions
from planners.postprocess import postprocess
from planners.st_astar import SpaceTimeAStar, TimedPath, plan_timed, without_waits

__all__ = ["CHECK_PERIOD_S", "MARGIN_M", "Request", "Result", "Settings", "blocked", "path_ahead", "solve"]

CHECK_PERIOD_S = 0.2  #: experiment seconds between two checks of the path ahead (5 Hz)
SAMPLE_M = 0.02  #: spacing (m) of the checked points along the path ahead
MARGIN_M = 0.02  #: clearance (m) beyond touching that counts as blocked; also the replanned path's planning margin
TIME_WINDOW_S = 1.0  #: the obstacles are checked this long (s) before and after the robot's predicted passage
_WINDOW_SAMPLES = 5
_RESOLUTION_M = 0.01  # grid of the replanning map, as the testbed's planners
_REPEAT_NAMES = {code: name for name, code in REPEAT_MODES.items()}


@dataclass(frozen=True)
class Settings:
    """A robot's replanning: how far ahead it looks (``horizon_s``, s of driving at ``speed_m_s``, m/s) and
    the least time between two replans (``min_interval_s``, s)."""

    horizon_s: float
    min_interval_s: float
    speed_m_s: float

    @classmethod
    def of(cls, controller: Selection | None, max_speed_m_s: float) -> "Settings | None":
        """The settings of a controller choice, None when it does not replan."""
        if controller is None or not controller.replans:
            return None
        p = controller.params
        return cls(p["replan_horizon_s"], p["replan_min_interval_s"], min(p.get("speed_m_s", max_speed_m_s),
                                                                           max_speed_m_s))


def path_ahead(path: np.ndarray, seg: int, frac: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(K, 2)`` (m) every :data:`SAMPLE_M` along ``path`` ``(P, 2+)`` from the projection at segment
    ``seg``, fraction ``frac``, over ``length`` (m) or to the path's end, and their arc distances ``(K,)`` (m)."""
    xy = np.asarray(path, dtype=float)[:, :2]
    if len(xy) < 2:
        return xy[:1].copy(), np.zeros(min(len(xy), 1))
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    seg = min(max(int(seg), 0), len(xy) - 2)
    s0 = cum[seg] + float(frac) * (cum[seg + 1] - cum[seg])
    d = np.arange(0.0, max(min(length, cum[-1] - s0), 0.0) + 1e-12, SAMPLE_M)
    s = s0 + d
    return np.column_stack([np.interp(s, cum, xy[:, 0]), np.interp(s, cum, xy[:, 1])]), d


def blocked(points: np.ndarray, times: np.ndarray, obstacles: Sequence[MovingObstacle], obstacle_time_s: float,
            robots: np.ndarray, radius: float) -> bool:
    """Whether the robot (collision ``radius``, m) passing ``points`` ``(K, 2)`` (m) at ``times`` ``(K,)`` (s from
    now) meets a moving obstacle (now at its time ``obstacle_time_s``, s) or a robot standing at ``robots``
    ``(R, 2)`` (m), with :data:`MARGIN_M` to spare (see the module docstring)."""
    if not len(points):
        return False
    if obstacles:
        offsets = np.linspace(-TIME_WINDOW_S, TIME_WINDOW_S, _WINDOW_SAMPLES)
        tt = np.maximum(obstacle_time_s + times[:, None] + offsets[None, :], 0.0).ravel()
        centres = positions(obstacles, tt).reshape(len(obstacles), len(points), _WINDOW_SAMPLES, 2)
        reach = np.array([o.radius for o in obstacles]) + radius + MARGIN_M
        gap = np.hypot(centres[..., 0] - points[None, :, None, 0], centres[..., 1] - points[None, :, None, 1])
        if (gap < reach[:, None, None]).any():
            return True
    if len(robots):
        gap = np.hypot(points[:, None, 0] - robots[None, :, 0], points[:, None, 1] - robots[None, :, 1])
        return bool((gap < 2.0 * radius + MARGIN_M).any())
    return False


@dataclass(frozen=True, eq=False)
class Request:
    """What a replan needs, in the robot's frame: its static map ``env`` (blocks, area; and its moving
    obstacles), its collision ``radius`` (m), where it is (``start`` x, y m), the ``goal`` (x, y m, theta
    rad), its obstacles' time now (``obstacle_time_s``, s), the ``others`` (robots standing where they are),
    and which robot and path it is for (``robot``, ``generation``)."""

    robot: int
    generation: int
    env: Environment
    radius: float
    start: tuple[float, float]
    goal: tuple[float, float, float]
    obstacle_time_s: float
    others: tuple[TimedPath, ...] = ()


@dataclass(frozen=True)
class Result:
    """A replan's new path ``(N, 3)`` (m, m, rad; None when none was found, ``why``) and its wall time (s)."""

    path: np.ndarray | None
    seconds: float
    why: str = ""


def static_map(size: tuple[float, float], blocks: np.ndarray, moving: Sequence[tuple[np.ndarray, np.ndarray]]) \
        -> Environment:
    """The replanning map of a robot's area ``size`` (m): its world's ``blocks`` ``(B, 5)`` (cx, cy, w, h m,
    angle rad) and its moving obstacles (``T,T,M``'s params (radius, speed, repeat code, delay) and waypoints
    ``(K, 2)``), all in its frame."""
    return Environment("replan", (float(size[0]), float(size[1])),
                       tuple(Block(*map(float, b)) for b in np.asarray(blocks).reshape(-1, 5)),
                       moving_obstacles=tuple(
                           MovingObstacle(float(p[0]), tuple((float(x), float(y)) for x, y in pts), float(p[1]),
                                          _REPEAT_NAMES[int(p[2])], float(p[3])) for p, pts in moving))


def solve(req: Request) -> Result:
    """Plan the robot's new path (pure: safe in a worker thread); never raises for a path not found."""
    t0 = time.perf_counter()
    start = np.array(req.start, dtype=float)
    try:
        space = config_space(req.env, req.radius + MARGIN_M, _RESOLUTION_M)
        if not space.is_free(start[None])[0]:  # the robot drove into the margin: plan from where it is
            space = config_space(req.env, req.radius, _RESOLUTION_M)
        timed, _ = plan_timed(space, start, np.array(req.goal[:2]), dict(SpaceTimeAStar.defaults),
                              others=req.others, obstacle_time_s=req.obstacle_time_s)
        raw, _ = without_waits(timed)
        path = postprocess(raw, space=space, final_heading=float(req.goal[2]))
    except (PlanningError, ValueError) as exc:
        return Result(None, time.perf_counter() - t0, str(exc))
    return Result(path, time.perf_counter() - t0)


def standing(points: np.ndarray, radius: float) -> tuple[TimedPath, ...]:
    """Robots standing at ``points`` ``(R, 2)`` (m), as the space-time planner's timed paths of ``radius`` (m)."""
    return tuple(TimedPath(np.asarray(p, dtype=float)[None, :2], np.zeros(1), float(radius))
                 for p in np.asarray(points).reshape(-1, 2))


def interval_steps(seconds: float, dt: float) -> int:
    """Control steps of ``dt`` (s) in ``seconds`` (s), at least one."""
    return max(1, int(math.ceil(seconds / dt - 1e-9)))


class Replanner:
    """The replanning state of a :class:`~robot_agent.engine.sim.SimCore`'s robots: each replanning robot's
    :class:`Settings`, the step of its next check and of its last replan, and its path's generation (a
    replan computed for an older path is dropped)."""

    def __init__(self, n: int, dt: float) -> None:
        self.dt = dt
        self.settings: dict[int, Settings] = {}
        self.next_check = np.zeros(n, dtype=np.int64)
        self.last = np.full(n, -(2 ** 62), dtype=np.int64)
        self.generation = np.zeros(n, dtype=np.int64)

    def begin(self, i: int, settings: Settings | None, step: int) -> None:
        """Robot ``i`` starts a path at ``step`` with ``settings`` (None: it does not replan)."""
        self.generation[i] += 1
        self.last[i] = -(2 ** 62)
        if settings is None:
            self.settings.pop(i, None)
        else:
            self.settings[i] = settings
            self.next_check[i] = step + interval_steps(CHECK_PERIOD_S, self.dt)

    def next_step(self, moving: np.ndarray) -> int | None:
        """The step of the next check of a moving replanning robot, None when there is none."""
        due = [int(self.next_check[i]) for i in self.settings if moving[i]]
        return min(due) if due else None

    def due(self, step: int, moving: np.ndarray) -> list[int]:
        """The moving replanning robots whose check is due at ``step``; their next check is set."""
        out = [i for i in sorted(self.settings) if moving[i] and self.next_check[i] <= step]
        for i in out:
            self.next_check[i] = step + interval_steps(CHECK_PERIOD_S, self.dt)
        return out

    def may_replan(self, i: int, step: int) -> bool:
        """Whether robot ``i``'s last replan is at least its ``min_interval_s`` before ``step``."""
        return step - self.last[i] >= interval_steps(self.settings[i].min_interval_s, self.dt)
