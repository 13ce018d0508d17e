"""The field: sub-fields, robots (and their registration), tracker pose ingestion."""

from __future__ import annotations

import anyio
from fastapi import APIRouter, Request

from ...errors import NotFound
from ...schemas import Page, RobotPublic, RobotRegister, SubfieldPublic, TrackerBatch
from ...tracking import parse_batch
from ..deps import AgentToken, CurrentUser, TestbedDep
from ..responses import AUTHENTICATED, errors

router = APIRouter(tags=["field"], responses=AUTHENTICATED)


@router.get("/subfields", response_model=Page[SubfieldPublic])
async def list_subfields(_: CurrentUser, testbed: TestbedDep) -> Page[SubfieldPublic]:
    """The four 1.8 m sub-fields: state, environment built, robot, current run."""
    data = testbed.field.subfield_views()
    return Page(data=data, count=len(data))


@router.get("/robots", response_model=Page[RobotPublic])
async def list_robots(_: CurrentUser, testbed: TestbedDep) -> Page[RobotPublic]:
    """Registered robots: field robots on sub-fields and the simulation pool."""
    data = testbed.field.robot_views(testbed.tracker.last_pose)
    return Page(data=data, count=len(data))


@router.post("/robots", response_model=RobotPublic, status_code=201, responses=errors(413))
async def register_robot(body: RobotRegister, _: AgentToken, testbed: TestbedDep) -> RobotPublic:
    """A robot agent announces itself (agent or admin token)."""
    slot = await testbed.field.register(body)
    testbed.dispatcher.wake()
    return testbed.field.robot_view(slot, testbed.tracker.last_pose(slot.robot_id))


@router.post("/tracker/poses", responses=errors(404, 413), openapi_extra={"requestBody": {"required": True, "content": {
    "application/json": {"schema": TrackerBatch.model_json_schema()}}}})
async def ingest_poses(request: Request, _: AgentToken, testbed: TestbedDep) -> dict:
    """A batch of tracker poses ``[t, x, y, theta]`` of one robot (agent or admin token).

    Body: :class:`TrackerBatch`.  Rows that are not four finite numbers are
    refused and counted in ``rejected``; the others are kept.  A robot the
    testbed does not know is refused (404): it must register first.
    """
    raw = await request.body()

    def work() -> dict:
        robot_id, poses, received = parse_batch(raw)
        if not testbed.field.known(robot_id):
            raise NotFound(f"Unknown robot {robot_id!r}: register it with POST /api/v1/robots first")
        stored, run_id = testbed.tracker.ingest(robot_id, poses)
        return {"received": received, "accepted": len(poses), "rejected": received - len(poses),
                "stored": stored, "run_id": run_id}

    return await anyio.to_thread.run_sync(work)
