"""A simulation-mode run as one compute-engine task (Ray): no agent, no socket, the same numbers.

The steps of :mod:`server.pipeline.runner` collapse into one task
(:func:`server.pipeline.compute.simulate_job`): the gripper's build and
placement (the jittered start when it is free, else the start), the path
through the wire codec, the ideal robot's simulation core stepped to the
end, the metrics.  The path itself is the experiment's, had once
(:mod:`server.pipeline.paths`).  Back on the server the poses go through
the tracker (stored, shown live), the protocol lines an agent would have
exchanged go to the run's log, and the end is classified as a robot's
``EV,FAIL`` is (:func:`server.pipeline.steps.failure_of`).
"""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np

from ..errors import FailureKind, RunFailed, TestbedFault
from ..models import utcnow
from ..status import RunStatus
from . import compute, steps
from .context import RunContext, RunServices

__all__ = ["run_on_engine"]


async def run_on_engine(ctx: RunContext, svc: RunServices) -> None:
    """Carry out the run as an engine task; raises as :func:`server.pipeline.runner` expects of its steps."""
    rec = svc.recorder
    job = await rec.job(ctx.run_id)
    plan = svc.paths.known(job.experiment_id)  # most runs of an experiment: planned already, one write less
    await rec.begin(ctx.run_id, status=RunStatus.PLANNING if plan is None else RunStatus.RUNNING,
                    robot_id=ctx.robot.robot_id, subfield=None, started_at=utcnow())
    if plan is None:
        plan = await svc.paths.path_for(job.experiment_id, run_id=ctx.run_id, robot_id=ctx.robot.robot_id,
                                        platform=ctx.robot.platform or "BeBot", on_line=ctx.on_line)
        await rec.update(ctx.run_id, status=RunStatus.RUNNING)
    start = steps.start_pose(job)
    jittered = compute.jittered(start, job.jitter, job.seed)
    starts = [jittered, start] if jittered != start else [start]
    ctx.on_line("s", f"simulated as a task on {ctx.robot.engine} ({ctx.robot.robot_id}): the lines below are "
                     "the ones an agent's robot would have exchanged", None, False)
    timeout_s = steps.run_timeout_s(svc, plan.path)
    out: dict[str, Any] = await svc.pool.run(compute.simulate_job, job.environment_data, plan.path, starts,
                                             job.seed, timeout_s, job.goal,
                                             job.robot_radius, plan.planning_time_s, job.controller,
                                             job.controller_params)
    for direction, line, t in out["lines"]:
        ctx.on_line(direction, line, t, False)
    if "placement_error" in out:
        raise TestbedFault(f"the gripper could not place the robot at the start: {out['placement_error']}")
    poses = np.asarray(out["poses"], dtype=float).reshape(-1, 4)
    svc.tracker.open(ctx.robot.robot_id, ctx.run_id, job.owner_id)
    try:
        await asyncio.to_thread(svc.tracker.ingest, ctx.robot.robot_id, poses)
    finally:
        svc.tracker.close(ctx.robot.robot_id)
    outcome = out["outcome"]
    t_end = out["t_end"]
    failure: RunFailed | TestbedFault | None = None
    if outcome == "TIMEOUT_SIM":
        t_end = float(poses[-1, 0]) if len(poses) else None
        failure = RunFailed(f"timeout: the robot did not finish within {timeout_s:.0f} s "
                            "of experiment time", FailureKind.TIMEOUT)
    elif outcome != "DONE":
        failure = steps.failure_of(outcome)
    if isinstance(failure, TestbedFault):
        raise failure
    fields: dict[str, Any] = {"t_start": out["t_start"], "t_end": t_end, "status": RunStatus.ANALYZING}
    if out["metrics"] is not None:
        metrics = dict(out["metrics"])
        metrics["collided"] = failure is not None and failure.kind is FailureKind.COLLISION
        fields["metrics"] = metrics
        if failure is not None and len(poses):
            fields["stopped_at"] = [round(float(poses[-1, 1]), 4), round(float(poses[-1, 2]), 4)]
    await rec.update(ctx.run_id, **fields)
    if failure is not None:
        raise failure
    if out["metrics"] is None:
        raise TestbedFault(f"cannot compute metrics: {out['metrics_error']}")
