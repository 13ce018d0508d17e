"""The field: sub-fields, robots (and their registration), tracker pose ingestion."""

from __future__ import annotations

from typing import Optional

import anyio
from fastapi import APIRouter, Request

from ...access import hidden_subfield_runs
from ...errors import Forbidden, NotFound
from ...schemas import Page, RobotPublic, RobotRegister, SubfieldPublic, TrackerBatch, TrackerBatchResult
from ...tracking import parse_batch
from ..deps import AgentToken, CurrentUser, TestbedDep
from ..responses import AUTHENTICATED, errors

router = APIRouter(tags=["field"], responses=AUTHENTICATED)


@router.get("/subfields", response_model=Page[SubfieldPublic])
async def list_subfields(user: CurrentUser, testbed: TestbedDep) -> Page[SubfieldPublic]:
    """The four 1.8 m sub-fields: state, environment built, robot, current and last run (if they are yours)."""
    field = testbed.field
    data = [v.model_copy(update=hidden_subfield_runs(user, field.subfield_owner.get(v.id), field.last_owner.get(v.id)))
            for v in field.subfield_views()]
    return Page(data=data, count=len(data))


@router.get("/robots", response_model=Page[RobotPublic])
async def list_robots(user: CurrentUser, testbed: TestbedDep) -> Page[RobotPublic]:
    """Registered robots: field robots on sub-fields and the simulation pool (a robot's last tracked
    pose while it runs someone else's run is not shown)."""
    tracker = testbed.tracker

    def last_pose(robot_id: str) -> Optional[list[float]]:
        owner = tracker.window_owner(robot_id)
        return tracker.last_pose(robot_id) if user.is_admin or owner in (None, user.id) else None

    data = testbed.field.robot_views(last_pose)
    return Page(data=data, count=len(data))


@router.post("/robots", response_model=RobotPublic, status_code=201, responses=errors(413))
async def register_robot(body: RobotRegister, who: AgentToken, testbed: TestbedDep) -> RobotPublic:
    """A robot agent announces itself (agent or admin token; a known robot only with the token that
    registered it, or an admin's)."""
    slot = await testbed.field.register(body, by=who)
    testbed.dispatcher.wake()
    return testbed.field.robot_view(slot, testbed.tracker.last_pose(slot.robot_id))


@router.post("/tracker/poses", response_model=TrackerBatchResult, responses=errors(404, 413),
             openapi_extra={"requestBody": {"required": True, "content": {
                 "application/json": {"schema": TrackerBatch.model_json_schema()}}}})
async def ingest_poses(request: Request, who: AgentToken, testbed: TestbedDep) -> TrackerBatchResult:
    """A batch of tracker poses ``[t, x, y, theta]`` of one robot (agent or admin token).

    Body: :class:`TrackerBatch`.  Rows that are not four finite numbers are
    refused and counted in ``rejected``; the others are kept.  A robot the
    testbed does not know is refused (404): it must register first; only the
    token that registered it (or an admin's) posts its poses (403).
    """
    raw = await request.body()

    def work() -> TrackerBatchResult:
        robot_id, poses, received = parse_batch(raw)
        if not testbed.field.known(robot_id):
            raise NotFound(f"Unknown robot {robot_id!r}: register it with POST /api/v1/robots first")
        if not testbed.field.may_track(robot_id, who):
            raise Forbidden(f"robot {robot_id!r} was registered with another token; only that token posts its poses")
        stored, run_id = testbed.tracker.ingest(robot_id, poses)
        return TrackerBatchResult(received=received, accepted=len(poses), rejected=received - len(poses),
                                  stored=stored, run_id=run_id)

    return await anyio.to_thread.run_sync(work)
