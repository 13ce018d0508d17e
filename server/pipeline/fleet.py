"""A multi-robot run as one task: every robot planned, driven in one world on one clock, measured.

docs/server.md, "Multi-robot jobs", describes such jobs.

The robots of a multi-robot job (``robots`` on the experiment) run together
in :func:`robot_agent.engine.jobs.fleet_job`, one task in the compute pool
(the worker processes, or Ray): planning (``prioritized`` together, any
other planner robot by robot; an uploaded program's paths, one per robot
port, had once per experiment before the task, are driven as sent), the simulation of all robots in one world
(they collide with each other), the fleet metrics.  A ``sim`` run is the
ideal robots; a ``twb`` run is the emulated field robots of the platform of
the field robot the scheduler gave it, computed as a task while the run
holds that robot and its sub-field (or the whole field), as a field run
with profile overrides is (:mod:`server.pipeline.remote`): no agent drives
them, the lines logged are the ones they would have exchanged.

Back on the server the run is played out at the time scale on a robot's
slot (:mod:`server.pipeline.playback`; at once on a compute engine's):
each robot is shown live as robot ``"<robot_id>/<k>"`` as its poses come
due and the protocol lines go to the run's log at their time, prefixed
``robot k:``.  The poses played are stored per robot (the ``robot``
column) with the run's end, and the run ends
``completed`` when every robot reached its goal, else ``failed`` naming
the robots and what they hit (:func:`fleet_failure`) -- measured either way.
"""

from __future__ import annotations

import json
import math
from typing import Any, Optional

import numpy as np

from contract.vocabulary import Mode
from robot_agent.engine import tasks

from ..errors import FailureKind, RunFailed, TestbedFault
from ..status import RunStatus, SubfieldState
from ..store.runs import RunJob
from .context import RunContext, RunServices
from .paths import Plan, placed
from .playback import Playback, play_run
from .steps import timeout_for_length_s

__all__ = ["fleet_failure", "fleet_poses", "fleet_timeout_s", "run_fleet"]

#: a robot's end as the run's failure: kind, and how the message says it (``{k}``: the robot's index)
_ENDS = {
    "TIMEOUT_SIM": (FailureKind.TIMEOUT, "robot {k} did not reach its goal within {s:.0f} s of experiment time"),
    "TIMEOUT": (FailureKind.CONTROLLER_TIMEOUT, "robot {k}'s controller gave up on its path"),
    "STALLED": (FailureKind.STALLED, "robot {k} could not make progress"),
}
#: which failure kind names a run whose robots failed in several ways (first wins)
_PRECEDENCE = (FailureKind.COLLISION, FailureKind.TIMEOUT, FailureKind.CONTROLLER_TIMEOUT, FailureKind.STALLED,
               FailureKind.OTHER)


def fleet_timeout_s(svc: RunServices, robots: list[dict[str, Any]]) -> float:
    """Experiment seconds a fleet may drive before its robots still under way count as timed out: the run
    timeout of one robot driving every robot's way one after the other (a prioritized plan may make robots
    wait for each other); a planned robot's way is its straight line times 1.5 (m)."""
    length = 0.0
    for r in robots:
        pts = r.get("path") or [r["start"], r["goal"]]
        straight = sum(math.dist(a[:2], b[:2]) for a, b in zip(pts[:-1], pts[1:]))
        length += straight if r.get("path") else 1.5 * straight
    return timeout_for_length_s(svc, length)


def fleet_poses(robots: list[dict[str, Any]]) -> np.ndarray:
    """Every robot's poses as one ``(N, 5)`` array: t s, x m, y m, theta rad, the robot's index; robot by robot."""
    parts = [np.column_stack([np.asarray(r["poses"], dtype=float).reshape(-1, 4), np.full(len(r["poses"]), k)])
             for k, r in enumerate(robots)]
    return np.concatenate(parts) if parts else np.zeros((0, 5))


def _hit_robot(k: int, robots: list[dict[str, Any]]) -> Optional[int]:
    """The robot nearest to robot ``k`` where and when ``k`` stopped (the one it collided with)."""
    me = np.asarray(robots[k]["poses"], dtype=float).reshape(-1, 4)
    if not len(me):
        return None
    t, x, y = me[-1, :3]
    best, gap = None, math.inf
    for j, r in enumerate(robots):
        p = np.asarray(r["poses"], dtype=float).reshape(-1, 4)
        if j == k or not len(p):
            continue
        d = math.hypot(float(np.interp(t, p[:, 0], p[:, 1])) - x, float(np.interp(t, p[:, 0], p[:, 2])) - y)
        if d < gap:
            best, gap = j, d
    return best


def _end_text(k: int, robot: dict[str, Any], measured: dict[str, Any], robots: list[dict[str, Any]],
              timeout_s: float) -> tuple[FailureKind, str]:
    """How robot ``k`` failed: its failure kind and a phrase naming it and what it hit."""
    outcome = robot["outcome"]
    if outcome == "COLLISION":
        kind = measured.get("collision")
        if kind == "moving" and robot.get("obstacle") is not None:
            o = robot["obstacle"]
            return FailureKind.COLLISION, f"robot {k} hit moving obstacle {o} (the environment's moving_obstacles[{o}])"
        other = _hit_robot(k, robots) if kind == "robot" else None
        if other is not None:
            return FailureKind.COLLISION, f"robot {k} hit robot {other}"
        return FailureKind.COLLISION, f"robot {k} hit a block or the wall"
    fkind, text = _ENDS.get(outcome, (FailureKind.OTHER, "robot {k}: " + outcome.lower().replace("_", " ")))
    return fkind, text.format(k=k, s=timeout_s)


def fleet_failure(robots: list[dict[str, Any]], metrics: dict[str, Any], timeout_s: float) -> Optional[RunFailed]:
    """The run's failure when a robot did not reach its goal (None when every one did): its kind is the
    gravest of the robots' (a collision before a timeout ...), its message names every robot that failed and
    what it hit, e.g. ``collision: robot 0 hit robot 2; robot 2 hit robot 0``, and says so when the fleet was
    deadlocked.  ``robots``: :func:`~robot_agent.engine.jobs.fleet_job`'s; ``metrics`` its fleet metrics."""
    ends = [_end_text(k, r, metrics["robots"][k], robots, timeout_s)
            for k, r in enumerate(robots) if r["outcome"] != "DONE"]
    if not ends:
        return None
    kind = min((fk for fk, _ in ends), key=_PRECEDENCE.index)
    label = {FailureKind.COLLISION: "collision", FailureKind.TIMEOUT: "timeout",
             FailureKind.CONTROLLER_TIMEOUT: "timeout", FailureKind.STALLED: "stalled"}.get(kind, "failed")
    text = f"{label}: " + "; ".join(t for _, t in ends)
    if metrics.get("deadlock"):
        text += f" (deadlock: no robot under way moved {metrics['settings']['progress_m']:g} m for " \
                f"{metrics['no_progress_max_s']:.1f} s)"
    failure = RunFailed(text, kind)
    first = next((r for r in robots if r["outcome"] == "COLLISION"), None)
    failure.obstacle = first.get("obstacle") if first is not None else None
    return failure


def _span(robots: list[dict[str, Any]]) -> tuple[Optional[float], Optional[float]]:
    """The fleet's ``t_start`` (the first robot's START) and ``t_end`` (the last robot's end, or its last pose
    when it did not end), s."""
    starts = [r["t_start"] for r in robots if r["t_start"] is not None]
    ends = []
    for r in robots:
        poses = np.asarray(r["poses"], dtype=float).reshape(-1, 4)
        end = r["t_end"] if r["t_end"] is not None else (float(poses[-1, 0]) if len(poses) else None)
        if end is not None:
            ends.append(end)
    return (min(starts) if starts else None), (max(ends) if ends else None)


async def run_fleet(ctx: RunContext, svc: RunServices, job: RunJob) -> None:
    """Carry out a multi-robot run as one task; raises as :func:`server.pipeline.runner` expects of its steps
    (:class:`RunFailed` when a robot did not arrive, planning included; :class:`TestbedFault` when the
    robots could not be placed)."""
    assert job.robots is not None
    on_field = job.mode == Mode.TWB
    platform = ctx.robot.platform or "BeBot"
    if on_field:
        svc.field.claim(ctx.subfields, job.owner_id)
        for k in ctx.subfields:
            await svc.field.set_subfield(k, state=SubfieldState.RUNNING, run_id=ctx.run_id, owner_id=job.owner_id)
        what = (f"{len(job.robots)} emulated field robots ({platform}"
                + (f", profile overrides {json.dumps(job.profile_overrides, sort_keys=True)}"
                   if job.profile_overrides else "")
                + f") on the field of {ctx.robot.robot_id}")
    else:
        what = f"{len(job.robots)} ideal robots on {ctx.robot.engine or 'the worker pool'} ({ctx.robot.robot_id})"
    robots, program_plan = job.robots, None
    if job.program is not None:
        robots, program_plan = await _program_paths(ctx, svc, job, platform)
    ctx.on_line("s", f"a multi-robot run of {what}, computed as one task in one world on one clock: the lines "
                     "below are the ones each robot would have exchanged, prefixed `robot k:`", None, False)
    timeout_s = fleet_timeout_s(svc, robots)
    out: dict[str, Any] = await svc.pool.run(
        tasks.FLEET, job.environment_data, robots, job.planner, job.planner_params, job.seed, timeout_s,
        job.robot_radius + job.planning_margin, "field" if on_field else "ideal", job.controller,
        job.controller_params, platform, job.profile_overrides if on_field else None,
        job.experiment_seed if job.planner_seed is None else job.planner_seed)
    if "planning_error" in out:  # a randomised planner's other repetitions plan with other seeds
        raise RunFailed(f"planning failed: {out['planning_error']}", FailureKind.PLANNING,
                        whole_experiment=not job.planner_stochastic)
    if "placement_error" in out:
        raise TestbedFault(f"the gripper could not place the robots: {out['placement_error']}")
    robots = out["robots"]
    await _keep_plan(svc, job, robots, out["planning_time_s"])
    if program_plan is not None:
        ctx.end_fields.update(program_plan.run_fields())
    else:  # the run's own plan: robot 0's path (every robot's is in the run's log), the fleet's planning
        ctx.end_fields.update(planned_path=robots[0]["path"], planning_time_s=out["planning_time_s"],
                              planning_cpu_s=out.get("planning_cpu_s"), planning_repeats=1,
                              planning_load=out.get("planning_load"))
    for k, r in enumerate(robots):
        for (w, held), why in zip(r["holds"], r.get("waited_for") or [[] for _ in r["holds"]]):
            ctx.on_line("s", f"robot {k}: held at waypoint {w} for {held:.2f} s, {_held_for(why)}", None, False)
    await _play(ctx, svc, job, robots, out["obstacles"])
    failure = fleet_failure(robots, out["metrics"], timeout_s)
    t_start, t_end = _span(robots)
    metrics = dict(out["metrics"])
    if program_plan is not None:  # the program's time to its last path, as a single robot's program's
        metrics["planning_time_s"] = program_plan.planning_time_s
    metrics["collided"] = any(r["outcome"] == "COLLISION" for r in robots)
    ctx.end_fields.update(t_start=t_start, t_end=t_end, metrics=metrics)
    if failure is not None:
        first = next(r for r in robots if r["outcome"] != "DONE")
        last = np.asarray(first["poses"], dtype=float).reshape(-1, 4)
        if len(last):
            ctx.end_fields["stopped_at"] = [round(float(last[-1, 1]), 4), round(float(last[-1, 2]), 4)]
        raise failure


async def _play(ctx: RunContext, svc: RunServices, job: RunJob, robots: list[dict[str, Any]],
                obstacles: Optional[list[np.ndarray]]) -> None:
    """Every robot's poses shown live and its lines logged (``robot k:``) as the run's experiment time passes
    at the time scale, on a robot's slot (at once on a compute engine's, as its single-robot runs are);
    the poses stored with the run's end are the ones played, all of them unless the run is cancelled, and
    so are the field's ``obstacles`` robots' (None in simulation: exact discs)."""
    lines = [(d, f"robot {k}: {line}", t) for k, r in enumerate(robots) for d, line, t in r["lines"]]
    playback = Playback([np.asarray(r["poses"], dtype=float).reshape(-1, 4) for r in robots], lines)
    try:
        await play_run(ctx, svc, job.owner_id, playback, fleet=True)
    finally:  # stored with the run's end, in its one transaction
        ctx.end_poses = fleet_poses([{"poses": playback.played(k)} for k in range(len(robots))])
        ctx.end_obstacles = playback.until_played(obstacles)


async def _program_paths(ctx: RunContext, svc: RunServices, job: RunJob,
                         platform: str) -> tuple[list[dict[str, Any]], Plan]:
    """The robots with the paths the experiment's program sent, one per robot port (run once per experiment,
    in this run's log: :meth:`~server.pipeline.paths.PathService.path_for`; the run is ``planning`` until
    then), placed as the program was told; raises :class:`~server.errors.ProgramFailed` naming the robots without a usable path."""
    assert job.robots is not None
    plan = await svc.paths.path_for(job.experiment_id, job.repetition, run_id=ctx.run_id,
                                    robot_id=ctx.robot.robot_id, platform=platform, on_line=ctx.on_line)
    assert plan.robots is not None and len(plan.robots) == len(job.robots)
    await svc.recorder.update(ctx.run_id, status=RunStatus.RUNNING)
    robots = [{"start": placed(r["start"], r["goal"]), "goal": r["goal"], "path": path, "headings": "sent"}
              for r, path in zip(job.robots, plan.robots)]
    return robots, plan


def _held_for(robots: list[int]) -> str:
    """Why a robot was held: for the robots it waited for (to pass first, as planned), else the plan's time."""
    if not robots:
        return "as planned"
    return "for robot" + ("s " if len(robots) > 1 else " ") + ", ".join(str(h) for h in robots) + " to pass first"


async def _keep_plan(svc: RunServices, job: RunJob, robots: list[dict[str, Any]],
                     planning_time_s: Optional[float]) -> None:
    """The experiment's plan, kept by a run of repetition 1 (both of its modes plan the same: the same planner
    seed): robot 0's path as ``planned_path`` (m, m, rad), every robot's path and departure times (s, None: no
    hold) in ``planning_info["robots"]``."""
    if job.repetition != 1:
        return
    stored, _ = await svc.recorder.planned_path(job.experiment_id)
    if stored is not None:
        return
    info = {"robots": [{"path": r["path"], "depart": r["depart"]} for r in robots],
            "explicit": job.planner is None}
    await svc.recorder.store_plan(job.experiment_id, robots[0]["path"], planning_time_s, info)
