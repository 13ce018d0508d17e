"""Runs: one run, its logged poses (JSON or CSV) and protocol messages."""

from __future__ import annotations

import io
from typing import Literal, Optional

from fastapi import APIRouter, Query
from fastapi.responses import PlainTextResponse
from sqlalchemy import func, select

from ...access import owned
from ...models import Message, Run
from ...schemas import RunPublic
from ...store.poses import run_poses
from ..deps import MAX_OFFSET, CurrentUser, IdPath, SessionDep
from ..responses import AUTHENTICATED, errors

router = APIRouter(prefix="/runs", tags=["runs"], responses=AUTHENTICATED)


@router.get("/{run_id:int}", response_model=RunPublic, responses=errors(404))
def get_run(run_id: IdPath, session: SessionDep, user: CurrentUser) -> RunPublic:
    """One run with its metrics."""
    return RunPublic.model_validate(owned(session, user, Run, run_id, "Run"))


_POSES_CONTENT = {"application/json": {"schema": {"type": "object", "properties": {
    "run_id": {"type": "integer"}, "count": {"type": "integer"}, "columns": {"type": "array", "items": {"type": "string"}},
    "poses": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}}}}},
    "text/csv": {"schema": {"type": "string"}}}


@router.get("/{run_id:int}/poses", response_model=None,
            responses={200: {"description": "The poses, as JSON or CSV.", "content": _POSES_CONTENT}, **errors(404)})
def get_poses(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    format: Literal["json", "csv"] = Query(default="json", description="json or csv (header t,x,y,theta)."),
    after_t: Optional[float] = Query(default=None, allow_inf_nan=False,
                                     description="Only poses later than this experiment time (s): for polling."),
):
    """Logged poses of a run, oldest first: tracker measurements (twb) or ground truth (sim).

    Times are experiment seconds on the robot's clock; x, y in metres and
    theta in radians, in the frame of the experiment's field.
    """
    owned(session, user, Run, run_id, "Run")
    rows = run_poses(session, run_id, after_t=after_t)
    if format == "csv":
        buf = io.StringIO()
        buf.write("t,x,y,theta\n")
        for t, x, y, a in rows:
            buf.write(f"{t:.4f},{x:.5f},{y:.5f},{a:.5f}\n")
        return PlainTextResponse(buf.getvalue(), media_type="text/csv",
                                 headers={"Content-Disposition": f'attachment; filename="run-{run_id}-poses.csv"'})
    return {"run_id": run_id, "count": len(rows), "columns": ["t", "x", "y", "theta"], "poses": rows}


@router.get("/{run_id:int}/messages", responses=errors(404))
def get_messages(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    offset: int = Query(default=0, ge=0, le=MAX_OFFSET),
    limit: int = Query(default=1000, ge=1, le=10000),
) -> dict:
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
    return {"data": [{"t": m.t, "t_estimated": m.t_estimated, "direction": m.direction, "line": m.line}
                     for m in rows], "count": count}
