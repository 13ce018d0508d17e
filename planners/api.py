"""One entry point for planning: validate, plan in the configuration space, post-process, time.

:func:`plan_path` is what the command line, the server and users call; it
treats built-in and plug-in planners the same way and guarantees that the
returned path starts at the start, ends at the goal and crosses only free
cells of the configuration space (cells whose centres keep the robot radius
and margin; the path itself keeps that less half a cell diagonal).
"""

from __future__ import annotations

import math
import os
import statistics
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional, Sequence

import numpy as np
from scipy import ndimage

from .environment import Environment, load_environment
from .errors import InvalidPose, NoPathFound, PlanningError
from .grid import ConfigSpace, config_space
from .postprocess import postprocess
from .registry import get_planner

__all__ = ["DEFAULT_PLANNING_MARGIN", "DEFAULT_ROBOT_RADIUS", "PlanResult", "TIMING_BUDGET_S", "TIMING_MAX_REPEATS",
           "check_query", "clearance_note", "components", "machine_load", "parse_pose", "plan_path"]

#: Radius (m) of the BeBot profile, the default robot; planners import nothing
#: from robot_agent, so the value is repeated here and checked by a test.
DEFAULT_ROBOT_RADIUS = 0.045

#: Clearance (m) the testbed's planners keep beyond the robot radius (docs/server.md, "The planning
#: margin"): field robots track a path only to within a few centimetres.  The configuration space
#: is the obstacles dilated by ``robot_radius + planning_margin``; the server's setting
#: ``planning_margin_m`` and ``twb plan``/``twb demo`` default to this value, so offline and
#: online plans agree.
DEFAULT_PLANNING_MARGIN = 0.02

#: a timed plan (``plan_path(timed=True)``) calls the planner again while its calls together took less than
#: this (s) ...
TIMING_BUDGET_S = 0.05
#: ... at most this many times in all, and reports the median: a fast planner's one call is at the mercy of a
#: scheduler tick, a slow one's is not
TIMING_MAX_REPEATS = 5


def machine_load() -> Optional[float]:
    """The machine's load when measured: the 1-minute load average per CPU (``os.getloadavg()[0] /
    os.cpu_count()``; about 1 when every core is busy), None where the system has none."""
    try:
        return round(os.getloadavg()[0] / (os.cpu_count() or 1), 4)
    except OSError:
        return None


@dataclass
class PlanResult:
    """A planned path and how it was obtained.

    ``path`` is ``(N, 3)``: x, y (m), heading (rad), post-processed and ready
    to send; ``raw_path`` ``(M, 2)`` is the planner's own output.
    ``planning_time_s`` is the wall time (s) of the planner call and
    post-processing, not of building the (cached) grid, which ``grid_time_s``
    reports when it happened; ``planning_cpu_s`` the CPU time of this process
    over the same call (s).  A timed plan (``plan_path(timed=True)``) reports
    the median of ``planning_repeats`` calls of each; ``planning_load`` is the
    machine's load when it was measured (:func:`machine_load`).
    """

    planner: str
    path: np.ndarray
    raw_path: np.ndarray
    length_m: float
    planning_time_s: float
    seed: int
    params: dict[str, Any]
    info: dict[str, Any] = field(default_factory=dict)
    robot_radius_m: float = DEFAULT_ROBOT_RADIUS
    planning_margin_m: float = 0.0
    planning_cpu_s: float = 0.0
    planning_repeats: int = 1
    planning_load: Optional[float] = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (docs/design.md, "Command line"): ``path``, ``length_m``, ``planning_time_s`` and details.

        ``robot_radius_m`` and ``planning_margin_m`` (m) say which configuration space it was planned in.
        """
        return {
            "planner": self.planner,
            "path": np.round(self.path, 6).tolist(),
            "length_m": round(self.length_m, 6),
            "planning_time_s": round(self.planning_time_s, 6),
            "seed": self.seed,
            "params": self.params,
            "raw_points": int(len(self.raw_path)),
            "robot_radius_m": self.robot_radius_m,
            "planning_margin_m": self.planning_margin_m,
            "info": self.info,
        }


def parse_pose(value: Sequence[float], what: str) -> np.ndarray:
    """``(x, y[, theta])`` as a float array of length 3 (theta NaN when not given)."""
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise InvalidPose(f"{what} must be numbers x, y[, theta], got {value!r}") from None
    if arr.size not in (2, 3):
        raise InvalidPose(f"{what} must have 2 or 3 numbers (x, y[, theta]), got {arr.size}")
    if not np.isfinite(arr).all():
        raise InvalidPose(f"{what} must be finite, got {arr.tolist()}")
    return np.r_[arr, np.nan] if arr.size == 2 else arr


def clearance_note(robot_radius: float, planning_margin: float) -> str:
    """How far from obstacles a pose must be, in words: ``"the robot radius 0.045 m"``, or with a
    margin ``"0.065 m (the robot radius 0.045 m plus the planning margin 0.02 m)"`` (metres)."""
    if planning_margin <= 0:
        return f"the robot radius {robot_radius:g} m"
    total = round(robot_radius + planning_margin, 9)
    return f"{total:g} m (the robot radius {robot_radius:g} m plus the planning margin {planning_margin:g} m)"


def _check_pose(space: ConfigSpace, pose: np.ndarray, what: str, note: str) -> None:
    env = space.env
    x, y = pose[:2]
    if not (0 <= x <= env.width and 0 <= y <= env.height):
        raise InvalidPose(
            f"{what} ({x:g}, {y:g}) is outside the field 0..{env.width:g} x 0..{env.height:g} m"
        )
    if not space.is_free(pose[None, :2])[0]:
        raise InvalidPose(f"{what} ({x:g}, {y:g}) is inside an obstacle or closer than {note} to one")


def components(space: ConfigSpace) -> np.ndarray:
    """Label of the 4-connected free region of every cell (0 where occupied), cached per space."""
    labels = space.__dict__.get("_labels")
    if labels is None:
        labels, _ = ndimage.label(space.free)
        object.__setattr__(space, "_labels", labels)
    return labels


def check_query(
    env: Environment | str,
    start: Sequence[float],
    goal: Sequence[float],
    *,
    robot_radius: float = DEFAULT_ROBOT_RADIUS,
    resolution: float = 0.01,
    planning_margin: float = 0.0,
) -> tuple[ConfigSpace, np.ndarray, np.ndarray]:
    """Check a planning query before any planning: returns ``(space, start, goal)``.

    The configuration space dilates the obstacles by ``robot_radius +
    planning_margin`` (m).  Poses come back as length-3 arrays (theta NaN
    when not given).  Raises :class:`InvalidPose` for a start or goal that is
    not finite, outside the field or not free, and :class:`NoPathFound` when
    the two lie in separate free regions.
    """
    env = load_environment(env)
    _check_margin(planning_margin)
    try:
        space = config_space(env, robot_radius + planning_margin, resolution)
    except PlanningError:
        raise
    except ValueError as exc:
        raise PlanningError(str(exc)) from exc
    note = clearance_note(robot_radius, planning_margin)
    s, g = parse_pose(start, "start"), parse_pose(goal, "goal")
    _check_pose(space, s, "start", note)
    _check_pose(space, g, "goal", note)
    labels = components(space)
    (sy, gy), (sx, gx) = space.grid.cell_of(np.array([s[:2], g[:2]]))
    if labels[sy, sx] != labels[gy, gx]:
        who = (f"a robot of radius {robot_radius:g} m" if planning_margin <= 0 else
               f"a robot of radius {robot_radius:g} m with a planning margin of {planning_margin:g} m")
        raise NoPathFound(
            f"the goal ({g[0]:g}, {g[1]:g}) cannot be reached from the start ({s[0]:g}, {s[1]:g}): "
            f"they are in separate free regions for {who}"
        )
    return space, s, g


def _check_margin(planning_margin: float) -> None:
    if not (isinstance(planning_margin, (int, float)) and math.isfinite(planning_margin) and planning_margin >= 0):
        raise PlanningError(f"`planning_margin` must be a finite number >= 0 (m), got {planning_margin!r}")


def plan_path(
    env: Environment | str,
    start: Sequence[float],
    goal: Sequence[float],
    planner: str = "fmm",
    *,
    robot_radius: float = DEFAULT_ROBOT_RADIUS,
    resolution: float = 0.01,
    params: Mapping[str, Any] | None = None,
    seed: int = 0,
    max_spacing: float = 0.1,
    tolerance: float = 0.005,
    planning_margin: float = 0.0,
    timed: bool = False,
    timing_budget_s: float = TIMING_BUDGET_S,
) -> PlanResult:
    """Plan a collision-free path from ``start`` to ``goal`` with the planner called ``planner``.

    Poses are ``(x, y[, theta])`` in metres/radians; ``robot_radius`` and
    ``resolution`` in metres; the path crosses only cells whose centres keep
    ``robot_radius + planning_margin`` (m) from every obstacle (the testbed
    plans with :data:`DEFAULT_PLANNING_MARGIN`), so by the exact distance it
    keeps at least that less ``resolution / sqrt(2)`` (docs/planners.md,
    "What clearance a path keeps"); ``max_spacing`` is the largest distance (m)
    between consecutive points of the returned path; ``tolerance`` (m) the
    largest deviation allowed when dropping points of the raw path.

    ``timed``: time the plan as a run's planning is timed (docs/study.md,
    "Planning time"): before every call the planner forgets what it kept from
    earlier ones (:meth:`~planners.base.Planner.forget`: each call plans from
    scratch), and a fast planner is called again while its calls together
    took less than ``timing_budget_s`` (s; default :data:`TIMING_BUDGET_S`; 0: one call), at most
    :data:`TIMING_MAX_REPEATS`
    times; the times are the medians and the path the first call's (the
    same seed gives the same path).  Otherwise the planner is called once.

    Raises :class:`~planners.errors.PlanningError` subclasses with a clear
    message: unknown planner, invalid environment or parameters, start/goal
    outside the field or not free, and no path.
    """
    env = load_environment(env)
    impl = get_planner(planner)
    try:
        checked = impl.validate_params(params)
        if not (isinstance(seed, int) and not isinstance(seed, bool)) or not 0 <= seed < 2**63:
            raise ValueError(f"`seed` must be an integer in [0, 2**63), got {seed!r}")
    except PlanningError:
        raise
    except ValueError as exc:
        raise PlanningError(str(exc)) from exc
    t0 = time.perf_counter()
    space, s, g = check_query(env, start, goal, robot_radius=robot_radius, resolution=resolution,
                              planning_margin=planning_margin)
    grid_time = time.perf_counter() - t0
    final = None if math.isnan(g[2]) else float(g[2])
    walls: list[float] = []
    cpus: list[float] = []
    first: Optional[tuple[np.ndarray, dict[str, Any], np.ndarray]] = None
    while True:
        if timed:
            impl.forget()
        c0, t0 = time.process_time(), time.perf_counter()
        got = _solve(impl, space, s, g, checked, seed, tolerance, max_spacing, final)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        first = first or got
        if not timed or len(walls) >= TIMING_MAX_REPEATS or sum(walls) >= timing_budget_s:
            break
    raw, info, path = first
    if not space.path_free(path):  # postprocess keeps chords free; this is a safety net
        raise PlanningError(f"internal error: post-processed {impl.name} path leaves free space")
    info = dict(info)
    if grid_time > 1e-3:
        info["grid_time_s"] = round(grid_time, 6)
    length = float(np.hypot(*np.diff(path[:, :2], axis=0).T).sum())
    return PlanResult(impl.name, path, raw, length, statistics.median(walls), seed, checked, info, robot_radius,
                      planning_margin, statistics.median(cpus), len(walls), machine_load())


def _solve(impl: Any, space: ConfigSpace, s: np.ndarray, g: np.ndarray, params: dict[str, Any], seed: int,
           tolerance: float, max_spacing: float,
           final: Optional[float]) -> tuple[np.ndarray, dict[str, Any], np.ndarray]:
    """One call of the planner and the post-processing: the raw path, the planner's info, the path to send."""
    try:
        out = impl.solve(space, s[:2].copy(), g[:2].copy(), params, seed)
    except PlanningError:
        raise
    except ValueError as exc:
        raise PlanningError(str(exc)) from exc
    raw, info = out if isinstance(out, tuple) else (out, {})
    raw = _check_raw(impl.name, np.asarray(raw, dtype=float), s, g, space)
    path = postprocess(raw, space=space, tolerance=tolerance, max_spacing=max_spacing, final_heading=final)
    return raw, info, path


def _check_raw(name: str, raw: np.ndarray, s: np.ndarray, g: np.ndarray, space: ConfigSpace) -> np.ndarray:
    """Refuse a planner result that is malformed, misses the ends or collides (plug-ins included)."""
    if raw.ndim != 2 or raw.shape[1] not in (2, 3) or len(raw) < 2:
        raise PlanningError(f"planner {name!r} returned an array of shape {raw.shape}, expected (N>=2, 2)")
    raw = raw[:, :2]
    if not np.isfinite(raw).all():
        raise PlanningError(f"planner {name!r} returned a path with NaN or inf")
    tol = space.resolution * 1e-6
    if np.hypot(*(raw[0] - s[:2])) > tol or np.hypot(*(raw[-1] - g[:2])) > tol:
        raise PlanningError(f"planner {name!r} returned a path that does not run from start to goal")
    i = space.first_blocked_segment(raw)
    if i is not None:
        raise PlanningError(
            f"planner {name!r} returned a path whose segment {i} ({raw[i][0]:.3f}, {raw[i][1]:.3f}) -> "
            f"({raw[i + 1][0]:.3f}, {raw[i + 1][1]:.3f}) enters an obstacle"
        )
    return raw
