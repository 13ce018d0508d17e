"""The field: sub-fields, robots (and their registration), tracker pose ingestion."""

from __future__ import annotations

import math

from fastapi import APIRouter, HTTPException

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
    """A batch of tracker poses ``[t, x, y, theta]`` of one robot (agent or admin token).

    Rows that are not four finite numbers are refused and counted in
    ``rejected``; the others are kept.  A robot the testbed does not know is
    refused (404): it must register first.
    """
    if body.robot_id not in testbed.scheduler.robots:
        raise HTTPException(404, f"Unknown robot {body.robot_id!r}: register it with POST /api/v1/robots first")
    rows = [r for r in body.poses if len(r) == 4 and all(math.isfinite(v) for v in r)]
    stored, run_id = testbed.router.ingest(body.robot_id, rows)
    return {"received": len(body.poses), "accepted": len(rows), "rejected": len(body.poses) - len(rows),
            "stored": stored, "run_id": run_id}
