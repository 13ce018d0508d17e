"""Pre-flight validation of a job before it is queued (as the Robotarium does).

Everything that would make a run fail for a reason known in advance is
refused here with a clear message: unknown environment or planner, bad
planner parameters, a start or goal outside the field or not free for the
robot, an unreachable goal, an explicit path leaving free space.  Pure
computation on the planners' model; no database, no robots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from contract.controller_specs import ControllerError
from contract.controller_specs import select as select_controller
from contract.frames import FIELD_SIZE, MAX_ROBOTS_SUBFIELD, SUBFIELD_SIZE
from planners import Environment, PlanningError, check_query, get_planner, parse_environment
from planners.moving import obstacle_at

from .errors import PreflightError
from .schemas import FLEET_PLANNER, FLEET_PLANNERS, MAX_ROBOTS, ExperimentCreate

__all__ = ["FIELD_SIZE", "MAX_ROBOTS", "SUBFIELD_SIZE", "Preflight", "PreflightError", "check_program_path",
           "check_program_paths", "preflight", "preflight_fleet"]


@dataclass(frozen=True)
class Preflight:
    """A checked job: the environment model, poses (theta NaN if not given), checked parameters."""

    env: Environment
    start: list[float]
    goal: list[float]
    planner_params: dict[str, Any]
    path: list[list[float]] | None
    controller_params: dict[str, float] = field(default_factory=dict)
    #: a multi-robot job's robots, ``{"start", "goal", "path"?}`` (m, rad); ``start``/``goal`` are robot 0's
    robots: list[dict[str, Any]] | None = None
    #: its planner is randomised (:attr:`planners.Planner.stochastic`): planned once per repetition
    stochastic: bool = False


def preflight(body: ExperimentCreate, env_data: dict[str, Any], robot_radius: float,
              planning_margin: float = 0.0) -> Preflight:
    """Validate ``body`` against the stored environment ``env_data``; raises :class:`PreflightError`.

    Planner jobs need the start and goal free for ``robot_radius +
    planning_margin`` (what the planner will keep); an explicit path and an
    uploaded program (whose path is checked when it arrives,
    :func:`check_program_path`) only need the robot radius itself.
    """
    env = _environment(body, env_data)
    try:
        controller = select_controller(body.controller, body.controller_params)
    except ControllerError as exc:
        raise PreflightError(f"{exc.field}: {exc}" if exc.field == "controller" else str(exc)) from None
    params = _planner_params(body)
    _tracked_robots(body, env)
    if body.robots is not None:
        if body.planner in FLEET_PLANNERS and controller.replans:
            raise PreflightError(f"controller_params.replan: the robots of a {body.planner} plan keep to its "
                                 "coordination and cannot replan (replan with an uncoordinated planner, e.g. fmm)")
        if body.planner == "lacam" and env.moving_obstacles:
            raise PreflightError(f"planner: lacam plans among the blocks only; environment {env.name!r} has "
                                 f"{len(env.moving_obstacles)} moving obstacle(s): plan with prioritized, which avoids them")
        robots = _fleet_robots(body, env, robot_radius, planning_margin)
        return Preflight(env, robots[0]["start"], robots[0]["goal"], params, None, controller.params, robots,
                         _stochastic(body))
    radius = robot_radius + (planning_margin if body.planner is not None else 0.0)
    try:
        space, s, g = check_query(env, body.start, body.goal, robot_radius=radius)
    except PlanningError as exc:
        note = (f" (the robot radius {robot_radius:g} m plus the testbed's planning margin {planning_margin:g} m)"
                if radius != robot_radius else "")
        raise PreflightError(f"{exc}{note}") from None
    taken = obstacle_at(env.moving_obstacles, s[:2], 0.0, robot_radius)
    if taken is not None:
        raise PreflightError(f"start ({s[0]:g}, {s[1]:g}) is closer than the robot radius {robot_radius:g} m to "
                             f"moving obstacle {taken} (moving_obstacles[{taken}]) when the path starts")
    path = None
    if body.path is not None:
        pts = np.array([p[:2] for p in body.path], dtype=float)
        if np.hypot(*(pts[0] - s[:2])) > 1e-3 or np.hypot(*(pts[-1] - g[:2])) > 1e-3:
            raise PreflightError("`path` must begin at `start` and end at `goal` (within 1 mm)")
        _check_clear(space, pts, robot_radius)
        path = [list(map(float, p)) for p in body.path]
    return Preflight(env, _pose(s), _pose(g), params, path, controller.params, stochastic=_stochastic(body))


def _stochastic(body: ExperimentCreate) -> bool:
    """Whether the job's planner is randomised (a program's declaration is read where the program is)."""
    if body.planner is None or body.planner in FLEET_PLANNERS:
        return False
    return bool(get_planner(body.planner).stochastic)


def _tracked_robots(body: ExperimentCreate, env: Environment) -> None:
    """On the field (mode ``twb``) each moving obstacle is a robot of the field the testbed drives: the job's
    robots and its moving obstacles must fit what the field's part holds (:data:`MAX_ROBOTS_SUBFIELD` on a
    sub-field, :data:`MAX_ROBOTS` on the whole field); PreflightError naming ``moving_obstacles``."""
    if "twb" not in body.modes or not env.moving_obstacles:
        return
    robots = len(body.robots) if body.robots is not None else 1
    most = MAX_ROBOTS if body.field == "full" else MAX_ROBOTS_SUBFIELD
    need = robots + len(env.moving_obstacles)
    if need > most:
        where = "a sub-field" if body.field == "sub" else "the field"
        hint = ' (use "field": "full" for up to 64)' if body.field == "sub" and need <= MAX_ROBOTS else ""
        raise PreflightError(
            f"moving_obstacles: {len(env.moving_obstacles)} moving obstacles and {robots} robot"
            f"{'s' if robots > 1 else ''} need {need} robots of the field (on the field each moving obstacle is a "
            f"robot the testbed drives); {where} holds {most}{hint}, or run mode \"sim\" alone, where they are "
            "exact discs")


def _environment(body: ExperimentCreate, env_data: dict[str, Any]) -> Environment:
    """The job's environment model, no larger than its field kind allows; PreflightError otherwise."""
    try:
        env = parse_environment(env_data)
    except PlanningError as exc:
        raise PreflightError(f"environment: {exc}") from None
    limit = SUBFIELD_SIZE if body.field == "sub" else FIELD_SIZE
    if env.width > limit[0] + 1e-9 or env.height > limit[1] + 1e-9:
        raise PreflightError(
            f"environment {env.name!r} is {env.width:g} x {env.height:g} m; a {body.field}-field job "
            f"allows at most {limit[0]:g} x {limit[1]:g} m" + (' (use "field": "full")' if body.field == "sub" else "")
        )
    return env


def _planner_params(body: ExperimentCreate) -> dict[str, Any]:
    """The planner's parameters, defaults filled in ({} without a planner); PreflightError naming a bad one."""
    if body.planner is None:
        return {}
    try:
        if body.planner == FLEET_PLANNER:
            from planners.prioritized import EXECUTIONS, check_fleet_params

            params = dict(body.planner_params)
            execution = params.pop("execution", EXECUTIONS[0])
            if execution not in EXECUTIONS:
                raise PreflightError(f"planner_params.execution: {' or '.join(map(repr, EXECUTIONS))} (how the robots "
                                     f"keep to the plan: in its order of passing, or by the clock), got {execution!r}")
            return {**check_fleet_params(params), "execution": execution}
        if body.planner == "lacam":
            from planners.lacam import check_lacam_params

            return check_lacam_params(body.planner_params)
        return get_planner(body.planner).validate_params(body.planner_params)
    except (PlanningError, ValueError) as exc:
        raise PreflightError(f"planner_params: {exc}" if body.planner in FLEET_PLANNERS else str(exc)) from None


def _fleet_robots(body: ExperimentCreate, env: Environment, robot_radius: float,
                  planning_margin: float) -> list[dict[str, Any]]:
    """A multi-robot job's robots checked (:func:`preflight_fleet`; each planned robot's goal reachable, each
    explicit path from its start to its goal and clear by ``robot_radius``, m); as plain ``{"start", "goal",
    "path"?}`` (m, rad).  Raises :class:`PreflightError` naming ``robots[i]...``."""
    assert body.robots is not None
    robots = [r.model_dump(exclude_none=True) for r in body.robots]
    margin = planning_margin if body.planner is not None else 0.0
    preflight_fleet(env, robots, robot_radius, margin, most=MAX_ROBOTS if body.field == "full" else MAX_ROBOTS_SUBFIELD)
    for i, r in enumerate(robots):
        explicit = r.get("path") is not None
        try:
            space, s, g = check_query(env, r["start"], r["goal"], robot_radius=robot_radius + (0.0 if explicit else margin))
        except PlanningError as exc:
            raise PreflightError(f"robots[{i}]: {exc}") from None
        if explicit:
            pts = np.array([p[:2] for p in r["path"]], dtype=float)
            if np.hypot(*(pts[0] - s[:2])) > 1e-3 or np.hypot(*(pts[-1] - g[:2])) > 1e-3:
                raise PreflightError(f"robots[{i}].path must begin at robots[{i}].start and end at robots[{i}].goal "
                                     "(within 1 mm)")
            try:
                _check_clear(space, pts, robot_radius)
            except PreflightError as exc:
                raise PreflightError(f"robots[{i}].{exc}") from None
    return robots


def preflight_fleet(env: Environment, robots: list[dict[str, Any]], robot_radius: float,
                    planning_margin: float = 0.0, most: int = MAX_ROBOTS_SUBFIELD) -> None:
    """Check a multi-robot job's ``robots`` (``{"start", "goal"}``, m, rad) in ``env``: 2 to ``most`` robots
    (:data:`MAX_ROBOTS_SUBFIELD` on a sub-field, :data:`MAX_ROBOTS` on the whole field), every start and goal free for ``robot_radius + planning_margin`` (m) and clear of the moving
    obstacles at time 0 (starts), no two starts or goals closer than twice that.  Raises
    :class:`PreflightError` naming the field (``robots[i].start`` ...)."""
    if not 2 <= len(robots) <= most:
        where = ("; a sub-field holds at most 16 (use \"field\": \"full\" for up to 64)"
                 if most < MAX_ROBOTS and len(robots) <= MAX_ROBOTS else "")
        raise PreflightError(f"robots: a multi-robot job has 2 to {most} robots, got {len(robots)}{where}")
    radius = robot_radius + planning_margin
    for i, r in enumerate(robots):
        for key in ("start", "goal"):
            try:
                check_query(env, r[key], r[key], robot_radius=radius)  # the pose alone
            except PlanningError as exc:
                why = str(exc).removeprefix("start ").removeprefix("goal ")
                raise PreflightError(f"robots[{i}].{key}: {key} {why}") from None
        taken = obstacle_at(env.moving_obstacles, np.asarray(r["start"][:2], dtype=float), 0.0, robot_radius)
        if taken is not None:
            raise PreflightError(f"robots[{i}].start is closer than the robot radius {robot_radius:g} m to moving "
                                 f"obstacle {taken} (moving_obstacles[{taken}]) when the paths start")
    for key in ("start", "goal"):
        xy = np.array([r[key][:2] for r in robots], dtype=float)
        d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.diag(np.full(len(xy), np.inf))
        if d.min() < 2 * radius:
            a, b = sorted(np.unravel_index(int(np.argmin(d)), d.shape))
            raise PreflightError(f"robots[{b}].{key} is {d[a, b]:.3f} m from robots[{a}].{key}: two robots need "
                                 f"{2 * radius:.3f} m between their centres")


def _check_clear(space: Any, pts: np.ndarray, robot_radius: float) -> None:
    """Every point and segment of ``pts`` free for the robot radius, else PreflightError naming the first."""
    outside = ~space.is_free(pts)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise PreflightError(
            f"path point {i} ({pts[i, 0]:g}, {pts[i, 1]:g}) is outside the field or closer than the "
            f"robot radius {robot_radius:g} m to an obstacle"
        )
    i = space.first_blocked_segment(pts)
    if i is not None:
        raise PreflightError(
            f"path segment {i} from ({pts[i, 0]:g}, {pts[i, 1]:g}) to ({pts[i + 1, 0]:g}, {pts[i + 1, 1]:g}) "
            f"passes closer than the robot radius {robot_radius:g} m to an obstacle"
        )


def check_program_path(env_data: dict[str, Any], start: list[float], goal: list[float], path: list[list[float]],
                       robot_radius: float, tolerance_m: float = 0.01) -> None:
    """The path an uploaded program sent: from the start to the goal (within ``tolerance_m``), collision-free.

    Raises :class:`PreflightError` with the reason (the run then ends
    ``failed``).  Pure; run it in a worker process.
    """
    try:
        space, s, g = check_query(parse_environment(env_data), start, goal, robot_radius=robot_radius)
    except PlanningError as exc:
        raise PreflightError(str(exc)) from None
    pts = np.array([p[:2] for p in path], dtype=float)
    if len(pts) < 2:
        raise PreflightError(f"the path has {len(pts)} point; it needs at least 2 (the start and the goal)")
    for name, p, q in (("begin at the start", pts[0], s), ("end at the goal", pts[-1], g)):
        d = float(np.hypot(*(p - q[:2])))
        if d > tolerance_m:
            raise PreflightError(f"the path must {name} ({q[0]:g}, {q[1]:g}) within {tolerance_m * 100:g} cm; "
                                 f"it is {d:.3f} m away at ({p[0]:g}, {p[1]:g})")
    _check_clear(space, pts, robot_radius)


def check_program_paths(env_data: dict[str, Any], starts: list[list[float]], goals: list[list[float]],
                        paths: list[list[list[float]]], robot_radius: float) -> list[Optional[str]]:
    """Each robot's path a multi-robot job's program sent, checked as :func:`check_program_path` checks one
    (m, rad): per robot, None or why its path is unusable.  Pure; run it in a worker process."""
    problems: list[Optional[str]] = []
    for start, goal, path in zip(starts, goals, paths):
        try:
            check_program_path(env_data, start, goal, path, robot_radius)
            problems.append(None)
        except PreflightError as exc:
            problems.append(str(exc))
    return problems


def _pose(p: np.ndarray) -> list[float]:
    return [float(p[0]), float(p[1])] + ([] if math.isnan(p[2]) else [float(p[2])])
