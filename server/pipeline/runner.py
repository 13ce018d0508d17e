"""One run, from its assignment to how it ended.

The steps, in order (each in :mod:`server.pipeline.steps`)::

    building   the gripper builds the environment (unless the robot has it built)
    placing    the gripper puts the robot at the start
    planning   the experiment's path, had once (server.pipeline.paths)
    running    the T,T,P line is sent, events followed, tracker poses stored
    analyzing  metrics, in a worker process
    completed

A simulation run on a compute engine's slot (Ray) is one task instead
(planning, running, analyzing: :mod:`server.pipeline.remote`).

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
from dataclasses import dataclass
from typing import Callable, Optional

from sqlalchemy.exc import DBAPIError

from ..errors import AgentRefused, AgentUnavailable, EngineFault, FailureKind, RunEnded, RunFailed, TestbedFault
from ..models import utcnow
from ..scheduler import Assignment
from ..status import RunStatus
from . import steps
from .context import RunContext, RunServices
from .remote import run_on_engine

__all__ = ["RunEnd", "execute_run"]

log = logging.getLogger("twb.runner")


@dataclass(frozen=True)
class RunEnd:
    """How a run ended: its status and error text.

    ``robot_fault``: the robot to avoid when retrying (``error`` only);
    ``whole_experiment``: the experiment's path could not be had, so its
    queued runs fail too, and ``failure`` why (``failed`` only); ``resume``:
    nobody's fault (the database went away), queue the run again.
    """

    status: RunStatus
    error: str = ""
    robot_fault: Optional[str] = None
    whole_experiment: bool = False
    failure: Optional[FailureKind] = None
    resume: bool = False


async def execute_run(assignment: Assignment, svc: RunServices, *, stopping: Callable[[], bool]) -> RunEnd:
    """Carry out one assigned run; returns how it ended (never raises; everything is stored).

    ``stopping()`` tells a testbed stop (``interrupted``) from a cancel
    (``cancelled``) when the run's task is cancelled.
    """
    ctx = RunContext(assignment, svc.field.robots[assignment.robot_id], svc.settings.time_scale,
                     svc.settings.run_slack_s)
    robot = ctx.robot.robot_id
    # an engine slot is not a robot: nothing to avoid on the retry, nothing to take offline
    blame = None if ctx.robot.engine else robot
    try:
        await (run_on_engine(ctx, svc) if ctx.robot.engine else _steps(ctx, svc))
        end = RunEnd(RunStatus.COMPLETED)
    except RunFailed as exc:
        end = RunEnd(RunStatus.FAILED, str(exc), whole_experiment=exc.whole_experiment, failure=exc.kind)
    except AgentRefused as exc:
        end = RunEnd(RunStatus.ERROR, f"robot {robot} refused a command: {exc}", robot_fault=robot)
    except AgentUnavailable as exc:
        end = RunEnd(RunStatus.ERROR, f"robot {robot}: {exc}", robot_fault=robot)
    except EngineFault as exc:
        end = RunEnd(RunStatus.ERROR, str(exc))
    except TestbedFault as exc:
        end = RunEnd(RunStatus.ERROR, str(exc), robot_fault=blame)
    except RunEnded as exc:
        end = RunEnd(exc.status, str(exc))
    except OSError as exc:
        end = RunEnd(RunStatus.ERROR, f"robot {robot}: {exc}", robot_fault=blame)
    except DBAPIError as exc:
        log.warning("run %d: the database went away: %s", ctx.run_id, exc.orig)
        end = RunEnd(RunStatus.INTERRUPTED, "the database was unreachable during this run", resume=True)
    except asyncio.CancelledError:
        end = (RunEnd(RunStatus.INTERRUPTED, "the server stopped during this run") if stopping()
               else RunEnd(RunStatus.CANCELLED, "cancelled by its owner"))
    except Exception as exc:  # noqa: BLE001 - a bug must end the run as an error, not kill the testbed
        log.exception("run %d crashed", ctx.run_id)
        end = RunEnd(RunStatus.ERROR, f"internal error: {type(exc).__name__}: {exc}", robot_fault=blame)
    finally:
        svc.tracker.close(robot)
    try:
        await asyncio.shield(svc.recorder.add_messages(ctx.take_messages()))
    except asyncio.CancelledError:
        pass
    except DBAPIError as exc:
        log.warning("run %d: the end of its protocol log is lost: %s", ctx.run_id, exc.orig)
    return end


async def _steps(ctx: RunContext, svc: RunServices) -> None:
    rec = svc.recorder
    job = await rec.job(ctx.run_id)
    svc.field.claim(ctx.subfields, job.owner_id)
    await rec.begin(ctx.run_id, status=RunStatus.BUILDING, robot_id=ctx.robot.robot_id,
                    subfield=ctx.subfields[0] if len(ctx.subfields) == 1 else None, started_at=utcnow())
    link = await steps.connect(ctx, svc)
    try:
        await link.request("T,T,Q", ctx.wall(0))  # anchors the agent's clock
        await steps.build(ctx, svc, link, job)
        await rec.update(ctx.run_id, status=RunStatus.PLACING)
        await steps.place(ctx, link, job)
        await rec.update(ctx.run_id, status=RunStatus.PLANNING)
        plan = await svc.paths.path_for(job.experiment_id, run_id=ctx.run_id, robot_id=ctx.robot.robot_id,
                                        platform=ctx.robot.platform or "BeBot", on_line=ctx.on_line)
        await rec.update(ctx.run_id, status=RunStatus.RUNNING)
        try:
            await steps.drive(ctx, svc, link, job, plan.path)
            failure: Optional[RunFailed] = None
        except RunFailed as exc:
            failure = exc
    finally:
        await link.close()
        await rec.add_messages(ctx.take_messages())
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
