"""The field: sub-fields, robots (and their registration), tracker pose ingestion."""

from __future__ import annotations

from fastapi import APIRouter

from ...schemas import Page, RobotPublic, RobotRegister, SubfieldPublic, TrackerBatch
from ..deps import AgentToken, CurrentUser, TestbedDep

router = APIRouter(tags=["field"])


@router.get("/subfields", response_model=Page[SubfieldPublic])
def list_subfields(_: CurrentUser, testbed: TestbedDep) -> Page[SubfieldPublic]:
    """The four 1.8 m sub-fields: state, environment built, robot, current run."""
    data = testbed.subfields()
    return Page(data=data, count=len(data))


@router.get("/robots", response_model=Page[RobotPublic])
def list_robots(_: CurrentUser, testbed: TestbedDep) -> Page[RobotPublic]:
    """Registered robots: field robots on sub-fields and the simulation pool."""
    data = testbed.robots()
    return Page(data=data, count=len(data))


@router.post("/robots", response_model=RobotPublic, status_code=201)
def register_robot(body: RobotRegister, _: AgentToken, testbed: TestbedDep) -> RobotPublic:
    """A robot agent announces itself (agent or admin token)."""
    return testbed.register_robot(body)


@router.post("/tracker/poses")
def ingest_poses(body: TrackerBatch, _: AgentToken, testbed: TestbedDep) -> dict:
    """A batch of tracker poses ``[t, x, y, theta]`` of one robot (agent or admin token)."""
    stored, run_id = testbed.router.ingest(body.robot_id, body.poses)
    return {"received": len(body.poses), "stored": stored, "run_id": run_id}
