"""One run, from its assignment to how it ended.

The steps, in order (each in :mod:`server.pipeline.steps`)::

    building   the gripper builds the environment (unless the robot has it built)
    placing    the gripper puts the robot at the start
    planning   the repetition's path: its own for a randomised planner, else the experiment's one,
               timed again per repetition (server.pipeline.paths)
    running    the T,T,P line is sent, events followed, tracker poses stored (or the job's
               controller program drives the robot: server.pipeline.closed_loop)
    analyzing  metrics, in a worker process
    completed

A simulation run on a compute engine's slot (Ray) is one task instead
(planning, running, analyzing: :mod:`server.pipeline.remote`), and so is a
field run whose job has profile overrides: the emulated field robot with
other parameters, computed in a worker while the run holds its robot and
sub-field (a robot's physics cannot be changed for one run).  A multi-robot
run is always one task, in both modes (:mod:`server.pipeline.fleet`).

Whose fault an ending is (:mod:`server.errors`): ``failed`` is the job's
(no path, collision, stall, timeout), ``error`` the testbed's (robot
unreachable, died, refused a command the pre-flight accepted; the
dispatcher retries it once elsewhere), ``interrupted`` a testbed stop,
``cancelled`` the owner's wish.  A run that failed on the field is measured
too: what it drove until then is data.  Every protocol line is logged.

:func:`execute_run` never raises: it returns a :class:`RunEnd` and leaves
the queue, the robots and the retry to its caller (:mod:`server.dispatch`).
"""

from __future__ import annotations

import asyncio
import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional

import numpy as np
from sqlalchemy.exc import DBAPIError

from contract.vocabulary import Mode

from ..errors import (
    AgentRefused,
    AgentUnavailable,
    AgentUnreachable,
    EngineFault,
    FailureKind,
    RunEnded,
    RunFailed,
    TestbedFault,
)
from ..models import Experiment, Run, utcnow
from ..scheduler import Assignment
from ..status import RunStatus
from ..store.runs import RunJob
from . import closed_loop, steps
from .context import RunContext, RunServices
from .fleet import run_fleet
from .recorder import RunRecorder
from .remote import run_on_engine, start_status

__all__ = ["RunEnd", "execute_run", "failure_text", "store_end"]

log = logging.getLogger("twb.runner")


@dataclass(frozen=True)
class RunEnd:
    """How a run ended: its status and error text.

    ``robot_fault``: the robot to avoid when retrying (``error`` only);
    ``whole_experiment``: the experiment's path could not be had, so its
    queued runs fail too, and ``failure`` why (``failed`` only); ``resume``:
    the run did not really begin (the database went away, or the robot could
    not be connected to), queue it again without counting a try.
    ``fields``, ``poses``, ``messages`` and ``obstacles``: what the run
    produced that is stored with its end (:meth:`RunRecorder.finish`).
    """

    status: RunStatus
    error: str = ""
    robot_fault: Optional[str] = None
    whole_experiment: bool = False
    failure: Optional[FailureKind] = None
    resume: bool = False
    #: stored with the end, in one transaction: run fields, poses (N, 4) (s, m, m, rad), protocol-log rows,
    #: a field run's obstacle robots' poses (per moving obstacle (T, 4), s, m, m, rad)
    fields: dict[str, Any] = field(default_factory=dict)
    poses: Optional[np.ndarray] = None
    messages: list[dict[str, Any]] = field(default_factory=list)
    obstacles: Optional[list[np.ndarray]] = None


async def execute_run(assignment: Assignment, svc: RunServices, *, stopping: Callable[[], bool]) -> RunEnd:
    """Carry out one assigned run; returns how it ended (never raises; everything is stored).

    ``stopping()`` tells a testbed stop (``interrupted``) from a cancel
    (``cancelled``) when the run's task is cancelled.
    """
    ctx = RunContext(assignment, svc.field.robots[assignment.robot_id], svc.settings.time_scale,
                     svc.settings.run_slack_s, log_lines=svc.settings.run_log_lines)
    robot = ctx.robot.robot_id
    try:
        await _carry_out(ctx, svc)
        end = RunEnd(RunStatus.COMPLETED)
    except RunFailed as exc:
        end = RunEnd(RunStatus.FAILED, str(exc), whole_experiment=exc.whole_experiment, failure=exc.kind)
    except AgentRefused as exc:
        end = RunEnd(RunStatus.ERROR, f"robot {robot} refused a command: {exc}", robot_fault=robot)
    except AgentUnreachable as exc:
        # nothing reached the robot: the run did not begin, so no attempt is spent; the robot goes offline
        end = RunEnd(RunStatus.ERROR, f"robot {robot}: {exc}", robot_fault=robot, resume=True)
    except AgentUnavailable as exc:
        end = RunEnd(RunStatus.ERROR, f"robot {robot}: {exc}", robot_fault=robot)
    except EngineFault as exc:
        end = RunEnd(RunStatus.ERROR, str(exc))
    except TestbedFault as exc:
        end = RunEnd(RunStatus.ERROR, str(exc), robot_fault=_blame(ctx))
    except RunEnded as exc:
        end = RunEnd(exc.status, str(exc))
    except OSError as exc:
        end = RunEnd(RunStatus.ERROR, f"robot {robot}: {exc}", robot_fault=_blame(ctx))
    except DBAPIError as exc:
        log.warning("run %d: the database went away: %s", ctx.run_id, exc.orig)
        end = RunEnd(RunStatus.INTERRUPTED, "the database was unreachable during this run", resume=True)
    except asyncio.CancelledError:
        end = (RunEnd(RunStatus.INTERRUPTED, "the server stopped during this run") if stopping()
               else RunEnd(RunStatus.CANCELLED, "cancelled by its owner"))
    except Exception as exc:  # noqa: BLE001 - a bug must end the run as an error, not kill the testbed
        log.exception("run %d crashed", ctx.run_id)
        end = RunEnd(RunStatus.ERROR, f"internal error: {type(exc).__name__}: {exc}", robot_fault=_blame(ctx))
    finally:
        svc.tracker.close(robot)
    ctx.finish_log()
    return replace(end, fields=ctx.end_fields, poses=ctx.end_poses, messages=ctx.take_messages(),
                   obstacles=ctx.end_obstacles)


async def store_end(recorder: RunRecorder, run_id: int, end: RunEnd) -> Optional[tuple[Run, Experiment]]:
    """Store how a run ended, in one transaction (:meth:`RunRecorder.finish`): an ``error`` is queued again
    once, a ``resume`` always; returns the run and experiment rows when queued again, else None."""
    return await recorder.finish(run_id, end.status, end.error, failure=failure_text(end), fields=end.fields,
                                 poses=end.poses, messages=end.messages, retry=end.status is RunStatus.ERROR,
                                 resume=end.resume, obstacles=end.obstacles)


def failure_text(end: RunEnd) -> Optional[str]:
    """The failure kind stored with a ``failed`` run."""
    return str(end.failure) if end.failure is not None and end.status is RunStatus.FAILED else None


def _blame(ctx: RunContext) -> Optional[str]:
    """The robot a testbed fault is held against: none for a task (an engine slot is not a robot, and a
    field-robot variant's task did not use it): nothing to avoid on the retry, nothing to take offline."""
    return None if ctx.as_task else ctx.robot.robot_id


async def _carry_out(ctx: RunContext, svc: RunServices) -> None:
    """A multi-robot run (:mod:`.fleet`), a run on a compute engine's slot or a field run with profile
    overrides (the emulated field robot with other parameters, :mod:`.remote`): one task; else the steps on
    the robot."""
    job = await svc.recorder.start(
        ctx.run_id, robot_id=ctx.robot.robot_id, started_at=utcnow(), clock=svc.settings.clock,
        time_scale=None if math.isinf(svc.settings.time_scale) else svc.settings.time_scale,
        subfield=ctx.subfields[0] if len(ctx.subfields) == 1 else None,
        status=lambda j: _first_status(ctx, svc, j))
    if job.robots is not None:
        ctx.as_task = True
        await run_fleet(ctx, svc, job)
    elif ctx.as_task or _as_task(job):
        ctx.as_task = True
        await run_on_engine(ctx, svc, job)
    else:
        await _steps(ctx, svc, job)


def _first_status(ctx: RunContext, svc: RunServices, job: RunJob) -> RunStatus:
    """The state a run starts in: a multi-robot run ``running`` (its task plans too; ``planning`` while an
    uploaded program plans it), another task as :func:`start_status` says, a run on a robot ``building``."""
    if job.robots is not None:
        return RunStatus.PLANNING if job.program is not None else RunStatus.RUNNING
    return start_status(svc, job) if ctx.as_task or _as_task(job) else RunStatus.BUILDING


def _as_task(job: RunJob) -> bool:
    """A field run with profile overrides runs as a task (the robot's physics cannot change for one run)."""
    return job.mode == Mode.TWB and bool(job.profile_overrides)


async def _steps(ctx: RunContext, svc: RunServices, job: RunJob) -> None:
    rec = svc.recorder
    svc.field.claim(ctx.subfields, job.owner_id)
    link = await steps.connect(ctx, svc)
    try:
        await link.request("T,T,Q", ctx.wall(0))  # anchors the agent's clock
        await steps.build(ctx, svc, link, job)
        await rec.update(ctx.run_id, status=RunStatus.PLACING)
        await steps.place(ctx, link, job)
        await rec.update(ctx.run_id, status=RunStatus.PLANNING)
        plan = await svc.paths.path_for(job.experiment_id, job.repetition, run_id=ctx.run_id,
                                        robot_id=ctx.robot.robot_id, platform=ctx.robot.platform or "BeBot",
                                        on_line=ctx.on_line)
        await rec.update(ctx.run_id, status=RunStatus.RUNNING, **plan.run_fields())  # the run's plan, kept
        try:
            if job.controller_program is not None:
                await closed_loop.drive_program(ctx, svc, link, job, plan)
            else:
                await steps.drive(ctx, svc, link, job, plan.path)
            failure: Optional[RunFailed] = None
        except RunFailed as exc:
            failure = exc
    finally:
        await link.close()
    await rec.update(ctx.run_id, status=RunStatus.ANALYZING)
    # a run that failed on the field (collision, stall, timeout) is measured too: what it drove until
    # then is data; its `collided` is the robot's own verdict, as for completed runs
    try:
        await steps.analyze(ctx, svc, job, plan, collided=failure is not None and failure.kind is FailureKind.COLLISION,
                            failed=failure is not None, obstacle=getattr(failure, "obstacle", None))
    except TestbedFault:
        if failure is None:
            raise
    if failure is not None:
        raise failure
