"""A simulation-mode run as one compute-engine task (Ray): no agent, no socket, the same numbers.

A field run whose job has profile overrides runs the same way, as the emulated field robot with those
parameters (:func:`robot_agent.engine.jobs.simulate_job` with the field backend), while it holds the robot
and sub-field the scheduler gave it; it is then played out at the time scale, as the robot would have
driven it (:mod:`server.pipeline.playback`).

The steps of :mod:`server.pipeline.runner` collapse into one task
(:func:`robot_agent.engine.jobs.simulate_job`): the gripper's build and
placement (the jittered start when it is free, else the start), the path
through the wire codec, the ideal robot's simulation core stepped to the
end, the metrics.  The path itself is the run's repetition's, had once
for both its modes (:mod:`server.pipeline.paths`).  Back on the server the poses go through
the tracker (stored, shown live), the protocol lines an agent would have
exchanged go to the run's log, and the end is classified as a robot's
``EV,FAIL`` is (:func:`server.pipeline.steps.failure_of`).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from contract.frames import FIELD_SIZE, SUBFIELD_SIZE
from contract.vocabulary import Mode
from robot_agent.engine import run_data, tasks

from ..errors import FailureKind, RunFailed, TestbedFault
from ..status import RunStatus
from ..store.runs import RunJob
from . import steps
from .context import RunContext, RunServices
from .playback import Playback, play_run

__all__ = ["run_on_engine", "start_status"]


def start_status(svc: RunServices, job: RunJob) -> RunStatus:
    """The state a task's run starts in: ``running``, or ``planning`` when its experiment has no path yet."""
    return RunStatus.RUNNING if svc.paths.known(job.experiment_id, job.repetition) else RunStatus.PLANNING


async def run_on_engine(ctx: RunContext, svc: RunServices, job: RunJob) -> None:
    """Carry out the run (started by the runner: ``job`` is its) as a task; raises as
    :func:`server.pipeline.runner` expects of its steps.  A field run (mode ``twb``, on a field robot) is
    the emulated field robot with the job's profile overrides, in the robot's frame, holding its sub-field."""
    rec = svc.recorder
    on_field = not ctx.robot.engine
    if job.controller_program is not None:
        raise RunFailed("a controller program drives a robot agent over TCP; this run went to a compute "
                        "engine's slot, which has none (run this job on a testbed without --sim-engine ray)",
                        FailureKind.OTHER)
    if on_field:
        svc.field.claim(ctx.subfields, job.owner_id)
    plan = svc.paths.known(job.experiment_id, job.repetition)  # a repetition's second run: one write less
    if plan is None:
        plan = await svc.paths.path_for(job.experiment_id, job.repetition, run_id=ctx.run_id,
                                        robot_id=ctx.robot.robot_id, platform=ctx.robot.platform or "BeBot",
                                        on_line=ctx.on_line)
        await rec.update(ctx.run_id, status=RunStatus.RUNNING)
    ctx.end_fields.update(plan.run_fields())  # the run's plan, stored with its end
    start = steps.start_pose(job)
    jittered = run_data.jittered(start, job.jitter, job.seed)
    starts = [jittered, start] if jittered != start else [start]
    platform = ctx.robot.platform or "BeBot"
    if on_field:
        ctx.on_line("s", f"the emulated field robot {ctx.robot.robot_id} ({platform}) with profile overrides "
                         f"{json.dumps(job.profile_overrides, sort_keys=True)}, computed as a task: the lines below "
                         "are the ones the robot would have exchanged", None, False)
    else:
        ctx.on_line("s", f"simulated as a task on {ctx.robot.engine} ({ctx.robot.robot_id}): the lines below are "
                         "the ones an agent's robot would have exchanged", None, False)
    timeout_s = steps.run_timeout_s(svc, plan.path)
    area = None if not on_field else (FIELD_SIZE if job.field == "full" else SUBFIELD_SIZE)
    out: dict[str, Any] = await svc.pool.run(tasks.SIMULATE, job.environment_data, plan.path, starts,
                                             job.seed, timeout_s, job.goal,
                                             job.robot_radius, plan.planning_time_s,
                                             "field" if job.mode == Mode.TWB else "ideal", platform,
                                             job.profile_overrides, area, job.controller, job.controller_params)
    if "placement_error" in out:
        for direction, line, t in out["lines"]:
            ctx.on_line(direction, line, t, False)
        raise TestbedFault(f"the gripper could not place the robot at the start: {out['placement_error']}")
    poses = np.asarray(out["poses"], dtype=float).reshape(-1, 4)
    playback = Playback([poses], out["lines"])
    try:  # on the field it takes its time (shown live, logged as it happens); on an engine's slot, at once
        await play_run(ctx, svc, job.owner_id, playback, fleet=False)
    finally:  # stored with the run's end, in its one transaction: what was played
        ctx.end_poses = playback.played(0)
        ctx.end_obstacles = playback.until_played(out["obstacles"])  # the field's obstacle robots (sim: None)
    outcome = out["outcome"]
    t_end = out["t_end"]
    failure: RunFailed | TestbedFault | None = None
    if outcome == "TIMEOUT_SIM":
        t_end = float(poses[-1, 0]) if len(poses) else None
        failure = RunFailed(f"timeout: the robot did not finish within {timeout_s:.0f} s "
                            "of experiment time", FailureKind.TIMEOUT)
    elif outcome != "DONE":
        failure = steps.failure_of(outcome, out.get("obstacle"))
    if isinstance(failure, TestbedFault):
        raise failure
    fields = ctx.end_fields
    fields.update(t_start=out["t_start"], t_end=t_end)
    if out["metrics"] is not None:
        metrics = dict(out["metrics"])
        metrics["collided"] = failure is not None and failure.kind is FailureKind.COLLISION
        metrics.update(run_data.collision_counts(metrics["collided"], out.get("obstacle")))
        fields["metrics"] = metrics
        if failure is not None and len(poses):
            fields["stopped_at"] = [round(float(poses[-1, 1]), 4), round(float(poses[-1, 2]), 4)]
    if failure is not None:
        raise failure
    if out["metrics"] is None:
        raise TestbedFault(f"cannot compute metrics: {out['metrics_error']}")
