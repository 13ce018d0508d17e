"""Runs: one run, its logged poses (JSON or CSV), its moving obstacles' tracks and protocol messages, its export."""

from __future__ import annotations

import io
from typing import Literal, Optional

from fastapi import APIRouter, Query
from fastapi.responses import JSONResponse, PlainTextResponse, StreamingResponse
from sqlalchemy import func, select

from ...access import owned
from ...export import ExportFormat
from ...export.load import run_record
from ...export.serve import download_headers, export_chunks, require_format
from ...models import Message, Run
from ...obstacles import run_obstacles
from ...schemas import MAX_ROBOTS, MessagePublic, Page, RunObstaclesPublic, RunPosesPublic, RunPublic
from ...store.poses import run_poses
from ..deps import MAX_OFFSET, CurrentUser, IdPath, SessionDep
from ..responses import AUTHENTICATED, EXPORTED, errors

router = APIRouter(prefix="/runs", tags=["runs"], responses=AUTHENTICATED)


@router.get("/{run_id:int}", response_model=RunPublic, responses=errors(404))
def get_run(run_id: IdPath, session: SessionDep, user: CurrentUser) -> RunPublic:
    """One run with its metrics."""
    return RunPublic.model_validate(owned(session, user, Run, run_id, "Run"))


# JSONResponse: the body encoded by json.dumps, byte for byte as before the route had a model (pydantic's JSON
# writes a small float without exponent: 9.8e-05 as 0.000098)
@router.get("/{run_id:int}/poses", response_model=RunPosesPublic, response_class=JSONResponse, responses={
    200: {"description": "The poses, as JSON or CSV (`format=csv`).",
          "content": {"text/csv": {"schema": {"type": "string"}}}},
    **errors(404)})
def get_poses(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    format: Literal["json", "csv"] = Query(default="json", description=(
        "json or csv (header t,x,y,theta; t,x,y,theta,robot for a multi-robot run).")),
    after_t: Optional[float] = Query(default=None, allow_inf_nan=False,
                                     description="Only poses later than this experiment time (s): for polling."),
    robot: Optional[int] = Query(default=None, ge=0, lt=MAX_ROBOTS, description=(
        "A multi-robot run: only this robot's poses (its index in the job's `robots`).")),
) -> RunPosesPublic | PlainTextResponse:
    """Logged poses of a run, oldest first: tracker measurements (twb) or ground truth (sim).

    Times are experiment seconds on the robot's clock; x, y in metres and
    theta in radians, in the frame of the experiment's field.  A multi-robot
    run's rows carry the robot's index as a fifth column (``robot``), robot by
    robot (robot 0's first), each robot's oldest first; ``robot=k`` keeps
    robot k's.
    """
    run = owned(session, user, Run, run_id, "Run")
    fleet = run.experiment.robots is not None
    rows = run_poses(session, run_id, after_t=after_t, robot=robot if fleet else None, fleet=fleet)
    if robot is not None and not fleet:
        rows = rows if robot == 0 else []  # one robot: robot 0 is the only one
    columns = ["t", "x", "y", "theta"] + (["robot"] if fleet else [])
    if format == "csv":
        buf = io.StringIO()
        buf.write(",".join(columns) + "\n")
        for row in rows:
            buf.write(f"{row[0]:.4f},{row[1]:.5f},{row[2]:.5f},{row[3]:.5f}" + (f",{row[4]}" if fleet else "") + "\n")
        return PlainTextResponse(buf.getvalue(), media_type="text/csv",
                                 headers={"Content-Disposition": f'attachment; filename="run-{run_id}-poses.csv"'})
    return RunPosesPublic(run_id=run_id, count=len(rows), columns=columns, poses=rows)


@router.get("/{run_id:int}/obstacles", response_model=RunObstaclesPublic, responses=errors(404))
def get_obstacles(run_id: IdPath, session: SessionDep, user: CurrentUser) -> RunObstaclesPublic:
    """Where the run's moving obstacles were: a field run's obstacle robots as the tracker saw them, else exact.

    One entry per moving obstacle of the environment (``index`` in its
    ``moving_obstacles``, ``radius`` m, ``count``, ``poses`` ``[t, x, y,
    theta]`` rows: experiment seconds on the run's clock, metres and radians
    in the frame of the experiment's field, oldest first).  ``exact`` false:
    the tracker's poses of the field's obstacle robots, stored with the run
    (each a robot of the run's radius); true: the exact tracks over the run,
    every 0.05 s (a simulation's; a field run whose obstacle robots could not
    be replayed, or that ran before they were stored).
    """
    run = owned(session, user, Run, run_id, "Run")
    return RunObstaclesPublic.model_validate({"run_id": run_id, "columns": ["t", "x", "y", "theta"],
                                              **run_obstacles(session, run)})


@router.get("/{run_id:int}/messages", response_model=Page[MessagePublic], responses=errors(404))
def get_messages(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    offset: int = Query(default=0, ge=0, le=MAX_OFFSET),
    limit: int = Query(default=1000, ge=1, le=10000),
) -> Page[MessagePublic]:
    """Every protocol line sent to (``>``) or received from (``<``) the robot, with experiment time.

    ``t`` is the agent's clock: exact for ``ST``/``EV`` lines, extrapolated
    from its last report for the others (``t_estimated``).  Jobs planned by an
    uploaded program also log its stdout (``o``), stderr (``e``) and its
    conversation with the sandbox's robot port (``s``).
    """
    owned(session, user, Run, run_id, "Run")
    rows = session.scalars(
        select(Message).where(Message.run_id == run_id).order_by(Message.id).offset(offset).limit(limit)
    ).all()
    count = session.scalar(select(func.count(Message.id)).where(Message.run_id == run_id)) or 0
    return Page(data=[MessagePublic.model_validate(m) for m in rows], count=count)


@router.get("/{run_id:int}/export", response_class=StreamingResponse, responses={**EXPORTED, **errors(404, 501)})
def export_run(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    format: ExportFormat = Query(default=ExportFormat.MCAP, description=(
        "mcap (Foxglove's well-known schemas) or rosbag2 (a ROS 2 bag directory, zipped).")),
) -> StreamingResponse:
    """The run as an MCAP file or a ROS 2 bag: poses, paths, scene, log and metrics on its clock.

    Topics (docs/exports.md): ``/tf`` and ``/robot/pose`` per stored pose,
    ``/robot/planned_path`` and ``/robot/driven_path``, ``/scene`` (blocks and
    moving obstacles), the log (``/log``; ``/rosout`` in a bag) and
    ``/metrics``; a multi-robot run's robots each under ``/robot_<k>``.  Times
    are experiment seconds on the run's clock (x 1e9 ns); poses in the
    ``map`` frame, the experiment's field (m, rad).  501 when the server lacks
    the ``export`` extra.
    """
    require_format(format)
    run = owned(session, user, Run, run_id, "Run")
    name = f"run-{run_id}"
    chunks, size = export_chunks([run_record(session, run)], format, name)
    return StreamingResponse(chunks, media_type=format.media_type,
                             headers=download_headers(format.filename(name), size))
