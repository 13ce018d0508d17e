"""A run's CPU work as jobs: plan, simulate, measure — the engine's function-call API for worker pools.

Jobs take and return plain JSON-ready data so they pickle cheaply to a
worker process or a Ray task; they never touch a database or the network.
The server names them through :mod:`.tasks` (so that it never loads the
compiled core itself); benchmarks and tests call them directly.  Units:
metres, radians, seconds.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any, Optional

import numpy as np

from contract.overrides import apply_overrides
from contract.params import robot_params
from contract.protocol import (
    MovingCommand,
    encode_build,
    encode_controller,
    encode_moving,
    encode_path,
    encode_place,
    parse_command,
)
from contract.robot_profile import load_profile, profile_for_platform
from planners import PlanningError, parse_environment, plan_path
from planners.api import TIMING_BUDGET_S
from planners.api import machine_load
from planners.control_metrics import ControlSettings, control_metrics
from planners.dependencies import fleet_dependencies
from planners.fast_marching import warm_up as warm_up_planners
from planners.fleet_metrics import FleetSettings, fleet_metrics
from planners.geometry import distance_to_obstacles
from planners.lacam import NAME as LACAM
from planners.lacam import lacam_schedule, plan_lacam
from planners.metrics import MetricSettings, obstacle_gaps, run_metrics
from planners.prioritized import EXECUTIONS, plan_prioritized, timed_waypoints

from .fleet import simulate_fleet
from .headless import PlacementRefused, simulate_run
from .limits import planning_limits
from .movers import mover_tracks
from .noise import path_key
from .run_data import TooFewPoses, block_tuples, explicit_path, json_safe, moving_tuples, replan_metrics, replanning

__all__ = ["field_obstacle_tracks", "fleet_job", "measure_run",
           "obstacle_robots_note", "plan_job", "simulate_job", "warm_up"]


def warm_up() -> bool:
    """Ready a fresh worker: import the numerical stack and load the compiled simulation core with one short
    run (about 1.4 s of CPU on this machine's cores), and the fast-marching planners' kernels with a tiny
    query, so its first real run and plan start at once."""
    simulate_job({"name": "warm-up", "size": [1.0, 1.0], "blocks": []}, [[0.3, 0.3, 0.0], [0.6, 0.3, 0.0]],
                 [[0.3, 0.3, 0.0]], 0, 60.0, [0.6, 0.3, 0.0], 0.045, 0.0)
    warm_up_planners()
    return True


def plan_job(env_data: dict[str, Any], start: list[float], goal: list[float], planner: str,
             params: dict[str, Any], seed: int, robot_radius: float,
             timing_budget_s: float = TIMING_BUDGET_S) -> dict[str, Any]:
    """Plan one repetition's path with its planner ``seed``, timed (docs/study.md, "Planning time"); returns
    ``{"path", "length_m", "planning_time_s", "planning_cpu_s", "planning_repeats", "planning_load", "info"}``.

    The times are the wall (``time.perf_counter``) and CPU (``time.process_time``) seconds of the planner call
    and its post-processing in this (warmed) worker, without building the cached grid; each call plans from
    scratch (the planner forgets its caches), and a fast planner is called again while its calls together
    took less than ``timing_budget_s`` (50 ms; the server's ``planning_timing_budget_s``), at most 5 times
    (``planning_repeats``), the times then being the medians;
    ``planning_load`` is the machine's 1-minute load average per CPU when it was measured.

    Raises :class:`planners.PlanningError` (no path, bad plug-in output, ...).
    """
    env = parse_environment(env_data)
    with planning_limits():
        r = plan_path(env, start, goal, planner, robot_radius=robot_radius, params=params, seed=seed, timed=True,
                      timing_budget_s=timing_budget_s)
    return {"path": np.round(r.path, 6).tolist(), "length_m": r.length_m,
            "planning_time_s": r.planning_time_s, "planning_cpu_s": r.planning_cpu_s,
            "planning_repeats": r.planning_repeats, "planning_load": r.planning_load, "info": r.info}


def measure_run(env_data: dict[str, Any], planned: list[list[float]], poses: list[list[float]],
                t_start: Optional[float], t_done: Optional[float], goal: list[float], robot_radius: float,
                planning_time_s: Optional[float], obstacles: Optional[list] = None) -> dict[str, Any]:
    """The metrics of one run (docs/metrics.md), the controller's too, from its planned path and logged poses
    ``[t, x, y, theta]``; ``obstacles`` (on the field): the tracker's poses of the obstacle robots, one
    ``[[t, x, y, theta], ...]`` per moving obstacle on the run's clock, which the obstacle metrics then
    measure against (each a robot of ``robot_radius``) instead of the exact tracks.

    Raises :class:`TooFewPoses` when fewer than two poses lie in the run.
    """
    env = parse_environment(env_data)
    pr = np.asarray(poses, dtype=float).reshape(-1, 4)
    if t_start is not None and t_done is not None:
        inside = (pr[:, 0] >= t_start - 1e-9) & (pr[:, 0] <= t_done + 1e-9)
        if inside.sum() >= 2:
            pr = pr[inside]
    if len(pr) < 2:
        raise TooFewPoses(f"only {len(pr)} pose(s) were logged for this run; metrics need at least 2")
    settings = MetricSettings(robot_radius=robot_radius)
    g = np.asarray(goal[:2], dtype=float)
    tracks = None
    if obstacles is not None:  # the obstacle clock starts with the path
        t0 = float(pr[0, 0]) if t_start is None else float(t_start)
        tracks = [np.asarray(o, dtype=float).reshape(-1, 4) - [t0, 0.0, 0.0, 0.0] for o in obstacles]
    out = run_metrics(np.asarray(planned, dtype=float), pr[:, 1:4], env=env, t=pr[:, 0], start_time=t_start,
                      done_time=t_done, goal=g, planning_time_s=planning_time_s, settings=settings,
                      obstacle_tracks=tracks, obstacle_radius=None if tracks is None else robot_radius)
    profile = robot_params()  # the testbed's robots: a collision is what their own check counts
    control = ControlSettings(collision_radius=profile.collision_radius_m, goal_tolerance=settings.goal_tolerance,
                              max_speed=profile.max_speed_m_s)
    out.update(control_metrics(planned, pr[:, 1:4], pr[:, 0], goal=g, env=env, performed_length_m=out["length_m"],
                               execution_time_s=out["execution_time_s"], settings=control))
    out["poses"] = int(len(pr))
    out["settings"] = {**settings.to_dict(), **control.to_dict()}
    return json_safe(out)


def obstacle_robots_note(env_data: dict[str, Any], platform: str) -> str:
    """The run log's line on a field run's moving obstacles: emulated robots of ``platform`` the testbed
    drives, and, when the environment gives them another radius, that on the field they have the robot's."""
    radius = robot_params(profile_for_platform(platform)).collision_radius_m
    obstacles = env_data.get("moving_obstacles") or []
    other = sorted({float(o["radius"]) for o in obstacles if float(o["radius"]) != radius})
    text = (f"the {len(obstacles)} moving obstacle(s) are emulated {platform} robots the testbed drives along their "
            f"tracks (they lag and deviate from the exact tracks, count toward the robots the tracker follows, "
            f"and stop when hit)")
    if other:
        text += (f"; a {platform} touches another robot at {2 * radius:.3f} m between centres (collision radius "
                 f"{radius:.3f} m), so the radius {', '.join(f'{r:g}' for r in other)} m the environment gives "
                 f"does not apply on the field: obstacle metrics measure them as robots of the run's radius")
    return text


def field_obstacle_tracks(env_data: dict[str, Any], seed: int, platform: str, t_start: float,
                          t_end: float) -> list[np.ndarray]:
    """The tracker's poses of a field run's obstacle robots from its path start ``t_start`` to its end
    ``t_end`` (s, the run's clock), replayed as the agent drove them for a path of noise seed ``seed``
    (:func:`robot_agent.engine.movers.mover_tracks`; the robot ``platform``'s profile): per moving obstacle
    ``(T, 4)`` t s, x m, y m, theta rad."""
    sent = parse_command(encode_moving(moving_tuples(env_data)))  # what the agent got: the wire's rounding
    assert isinstance(sent, MovingCommand)
    params = robot_params(load_profile(profile_for_platform(platform)))
    return [tr + [t_start, 0.0, 0.0, 0.0]
            for tr in mover_tracks(list(sent.obstacles), path_key(seed), params, t_end - t_start)]


def _replans(events: list[Any]) -> list[tuple[int, float]]:
    """A simulated run's ``REPLAN`` events as :func:`replan_metrics` takes them (points, planning time s)."""
    return [(e.index or 0, e.seconds or 0.0) for e in events if e.kind == "REPLAN"]


def simulate_job(env_data: dict[str, Any], path: list[list[float]], starts: list[list[float]], seed: int,
                 max_s: float, goal: list[float], robot_radius: float,
                 planning_time_s: Optional[float], backend: str = "ideal", platform: str = "BeBot",
                 overrides: Optional[dict[str, float]] = None, area: Optional[tuple[float, float]] = None,
                 controller: str = "schema", controller_params: Optional[dict[str, float]] = None) -> dict[str, Any]:
    """One run without a robot agent (a Ray or worker-process task): the ``backend`` robot (``ideal``; or
    ``field``, the emulated field robot of ``platform``'s profile with the field parameters ``overrides``)
    follows ``path`` with ``controller`` and its ``controller_params`` from the first free pose of
    ``starts`` (x, y, theta; m, rad: the jittered start, then the start itself) among the environment's
    blocks and moving obstacles in a world of ``area`` (m; default the whole field) for at most ``max_s``
    experiment seconds, as an agent's robot would (:func:`robot_agent.engine.headless.simulate_run`), then is
    measured.

    Returns ``{"poses"`` ``(N, 4)`` t s, x m, y m, theta rad (field frame), ``"lines"`` the protocol
    lines an agent would have exchanged (``[direction, line, t]``), ``"t_start"``, ``"t_end"``,
    ``"outcome"`` (``DONE``, a ``FAIL`` reason or ``TIMEOUT_SIM``), ``"obstacle"`` (the moving obstacle of a
    collision, else None), ``"obstacles"`` (on the field: the tracker's poses of the obstacle robots, per
    obstacle ``(T, 4)`` on the run's clock; else None), ``"metrics"`` (None with
    ``"metrics_error"`` when too few poses were logged)``}``; or ``{"placement_error": why, "lines"}`` when no
    pose of ``starts`` is free.
    """

    pause = float(os.environ.get("TWB_FAULT_SIM_PAUSE_S", "0") or 0)  # fault injection (tests): a run in progress
    if pause > 0:
        time.sleep(pause)
    blocks = block_tuples(env_data)
    profile = apply_overrides(load_profile(profile_for_platform(platform)), overrides)
    moving = moving_tuples(env_data)
    lines: list[list[Any]] = [[">", encode_build(blocks), None]]
    if moving:
        lines.append([">", encode_moving(moving), None])
        if backend == "field":
            lines.append(["s", obstacle_robots_note(env_data, platform), None])
    run = None
    for i, start in enumerate(starts):
        lines.append([">", encode_place(start), None])
        try:
            run = simulate_run(path, start, seed=seed, blocks=blocks, moving=moving, max_s=max_s, backend=backend,
                               profile=profile, controller=controller, controller_params=controller_params,
                               **({} if area is None else {"area": tuple(area)}))
            break
        except PlacementRefused as exc:
            lines.append(["<", f"ERR,RANGE,{exc}", None])
            if i + 1 == len(starts):
                return {"placement_error": str(exc), "lines": lines}
            lines.append(["s", f"the jittered start is not free ({exc}); placing at the start itself", None])
    assert run is not None
    if controller != "schema":
        lines.append([">", encode_controller(controller, controller_params), None])
    lines.append([">", encode_path(path), run.t_start])
    lines += [["<", e.line, e.t] for e in run.events]
    out: dict[str, Any] = {"poses": run.poses, "lines": lines, "t_start": run.t_start, "t_end": run.t_end,
                           "outcome": run.outcome, "obstacle": run.obstacle, "metrics": None, "metrics_error": None,
                           "obstacles": run.obstacles}
    t_end = run.t_end if run.t_end is not None else (float(run.poses[-1, 0]) if len(run.poses) else None)
    try:
        out["metrics"] = measure_run(env_data, path, run.poses, run.t_start, t_end, goal, robot_radius,
                                     planning_time_s, run.obstacles)
        if replanning(controller_params):
            out["metrics"].update(replan_metrics(_replans(run.events)))
    except TooFewPoses as exc:
        out["metrics_error"] = str(exc)
    return out


def fleet_job(env_data: dict[str, Any], robots: list[dict[str, Any]], planner: Optional[str],
              params: dict[str, Any], seed: int, max_s: float, robot_radius: float, backend: str = "ideal",
              controller: str = "schema", controller_params: Optional[dict[str, float]] = None,
              platform: str = "BeBot", overrides: Optional[dict[str, float]] = None,
              plan_seed: Optional[int] = None, execution: str = "dependencies") -> dict[str, Any]:
    """A multi-robot run as one task (docs/server.md, "Multi-robot jobs"): plan every robot, run them all in one world
    on one clock (:func:`robot_agent.engine.fleet.simulate_fleet`), measure them
    (:func:`planners.fleet_metrics.fleet_metrics`).

    ``robots``: per robot ``{"start", "goal", "path"?}`` (m, rad).  ``planner`` ``lacam`` plans them together
    on a grid (:mod:`planners.lacam`), executed by the plan's order of passage alone (no clock: ``execution``
    must be ``dependencies``); ``prioritized`` plans them
    together (timed paths) and ``execution`` says how the robots keep to it: ``dependencies`` (a robot
    leaves a waypoint once the robots planned to pass there before it have passed, and not before the
    plan's wait there ends: :mod:`planners.dependencies`) or ``timed`` (by the clock alone: robots hold
    where the plan waits, late ones drive on; ``params["execution"]``, a job's choice, wins); any other planner plans each robot alone,
    uncoordinated (the baseline); a robot's explicit ``path`` is driven as given (its headings facing the next
    point; with ``"headings": "sent"``, an uploaded program's ``[x, y, theta]`` path, as they are).  Planning keeps
    ``robot_radius`` (m) and samples with ``plan_seed`` (default ``seed``); ``seed`` gives the robots' noise.
    The robots are ``backend`` robots (``ideal``, or ``field``: the emulated field robot of ``platform``'s
    profile with the field parameters ``overrides``) following with ``controller`` for at most ``max_s``
    experiment seconds.  Returns ``{"robots": [per robot {"path", "depart", "poses" (N, 4) t s, x m, y m,
    theta rad, "lines", "t_start", "t_end", "outcome", "obstacle", "holds" [[waypoint, s held], ...],
    "waited_for" [[robot, ...] per hold]}], "planning_time_s", "planning_cpu_s" (wall and CPU seconds of planning
    every robot, once), "planning_load" (the machine's load per CPU), "metrics", "obstacles"}`` (``"obstacles"``: on
    the field the tracker's poses of the obstacle robots, per moving obstacle ``(T, 4)`` on the fleet's clock;
    else None),
    or ``{"planning_error": why}`` / ``{"placement_error": why}``."""

    env = parse_environment(env_data)
    c0, t0 = time.process_time(), time.perf_counter()
    paths: list[list[list[float]]] = []
    depart: list[Optional[list[float]]] = []
    depends = None
    if planner == "prioritized":  # the job's own choice, kept with its planner's parameters
        params = dict(params)
        execution = params.pop("execution", execution)
    if execution not in EXECUTIONS:
        raise ValueError(f"execution is 'dependencies' or 'timed', got {execution!r}")
    try:
        with planning_limits():  # the worker's memory cap and the planning deadline
            if planner == "prioritized":
                plan = plan_prioritized(env, [r["start"] for r in robots], [r["goal"] for r in robots],
                                        robot_radius=robot_radius, params=params)
                dense = execution == "dependencies"
                schedule = [timed_waypoints(t, r["goal"][2] if len(r["goal"]) > 2 else None, dense)
                            for r, t in zip(robots, plan.paths)]
                for pts, arrive, leave in schedule:
                    paths.append(np.round(pts, 6).tolist())
                    depart.append([float(b) if b > a + 1e-9 and k < len(pts) - 1 else None
                                   for k, (a, b) in enumerate(zip(arrive, leave))])
                if dense:
                    depends = fleet_dependencies([w for w, _, _ in schedule], [a for _, a, _ in schedule],
                                                 [lv for _, _, lv in schedule], plan.conflict_m)
            elif planner == LACAM:  # together on the grid, executed by the plan's order of passage only
                if execution != "dependencies":
                    raise ValueError("a lacam plan is executed by its order of passage (execution 'dependencies')")
                lacam = plan_lacam(env, [r["start"] for r in robots], [r["goal"] for r in robots],
                                   robot_radius=robot_radius, params=params,
                                   seed=seed if plan_seed is None else plan_seed)
                headings = [r["goal"][2] if len(r["goal"]) > 2 else None for r in robots]
                wps, _, _, depends = lacam_schedule(lacam, headings)
                for w in wps:
                    paths.append(np.round(w, 6).tolist())
                    depart.append(None)  # no clock: the order of passage alone releases the robots
            else:
                for i, r in enumerate(robots):
                    if r.get("headings") == "sent":  # an uploaded program's path: headings as it sent them
                        paths.append(np.round(np.asarray(r["path"], dtype=float), 6).tolist())
                    elif r.get("path") is not None:
                        paths.append(explicit_path(r["path"], r["goal"]))
                    else:
                        try:
                            got = plan_path(env, r["start"], r["goal"], planner or "fmm", robot_radius=robot_radius,
                                            params=params, seed=seed if plan_seed is None else plan_seed)
                        except PlanningError as exc:
                            raise PlanningError(f"robot {i}: {exc}") from None
                        paths.append(np.round(got.path, 6).tolist())
                    depart.append(None)
    except PlanningError as exc:
        return {"planning_error": str(exc)}
    planning_time_s = time.perf_counter() - t0
    planning_cpu_s = time.process_time() - c0
    starts = []
    for r, p in zip(robots, paths):
        s = list(r["start"])
        starts.append(s if len(s) > 2 else [*s[:2], p[0][2]])
    dep_arrays = [None if d is None else np.array([np.nan if v is None else v for v in d]) for d in depart]
    profile = apply_overrides(load_profile(profile_for_platform(platform)), overrides)
    try:
        fleet = simulate_fleet(paths, starts, seed=seed, depart=dep_arrays, blocks=block_tuples(env_data),
                               moving=moving_tuples(env_data), backend=backend, profile=profile, area=env.size,
                               max_s=max_s, controller=controller, controller_params=controller_params,
                               depends=depends)
    except PlacementRefused as exc:
        return {"placement_error": str(exc)}
    settings = FleetSettings(robot_radius=robot_params().collision_radius_m)
    last = [r.poses[-1, 1:3] if len(r.poses) else None for r in fleet.runs]
    clearance = [None if p is None else float(distance_to_obstacles(env, p[None])[0]) for p in last]
    metrics = fleet_metrics([r.poses for r in fleet.runs], fleet.outcomes, [r.t_end for r in fleet.runs],
                            [r.obstacle for r in fleet.runs], settings, clearance)
    if env.moving_obstacles:
        _fleet_obstacle_distances(env, fleet, robot_params(profile).collision_radius_m if backend == "field" else None,
                                  metrics)
    metrics["planning_time_s"] = planning_time_s
    if replanning(controller_params):
        per = [replan_metrics(_replans(r.events)) for r in fleet.runs]
        for row, m in zip(metrics["robots"], per):
            row.update(m)
        metrics.update({k: sum(m[k] for m in per) for k in ("replans", "replan_failures", "replan_time_s")})
    out = []
    for i, run in enumerate(fleet.runs):
        lines = [] if i or backend != "field" or not env.moving_obstacles else \
            [["s", obstacle_robots_note(env_data, platform), None]]
        lines.append([">", encode_path(paths[i]), run.t_start])
        lines += [["<", e.line, e.t] for e in run.events]
        out.append({"path": paths[i], "depart": depart[i], "poses": run.poses, "lines": lines,
                    "t_start": run.t_start, "t_end": run.t_end, "outcome": run.outcome, "obstacle": run.obstacle,
                    "holds": [[int(k), float(s)] for k, s in fleet.holds[i]],
                    "waited_for": [[int(h) for h in w] for w in fleet.waited_for[i]]})
    return {"robots": out, "planning_time_s": planning_time_s, "planning_cpu_s": planning_cpu_s,
            "planning_load": machine_load(), "metrics": json_safe(metrics), "obstacles": fleet.obstacles}


def _fleet_obstacle_distances(env: Any, fleet: Any, obstacle_radius: Optional[float], metrics: dict[str, Any]) -> None:
    """``obstacle_distance_min_m`` (m) of every robot of a fleet run (``metrics["robots"]``) while under way, and
    the fleet's smallest: robot discs of the fleet settings' radius to the moving obstacles where they were
    (on the field the obstacle robots' tracker poses, each a robot of ``obstacle_radius``; else the exact
    tracks), on the fleet's clock."""
    radius = metrics["settings"]["robot_radius"]
    smallest = None
    for run, row in zip(fleet.runs, metrics["robots"]):
        p = run.poses
        end = run.t_end if run.t_end is not None else math.inf
        p = p[p[:, 0] <= end + 1e-9] if len(p) else p
        gap = None
        if len(p):
            gap = float(obstacle_gaps(env, p[:, 1:3], p[:, 0], radius, fleet.obstacles, obstacle_radius).min())
            smallest = gap if smallest is None else min(smallest, gap)
        row["obstacle_distance_min_m"] = gap
    metrics["obstacle_distance_min_m"] = smallest
