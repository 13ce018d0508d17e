"""The field: sub-fields, robots (and their registration), tracker pose ingestion."""

from __future__ import annotations

import json

import anyio
import numpy as np
from fastapi import APIRouter, HTTPException, Request

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


@router.post("/tracker/poses", openapi_extra={"requestBody": {"required": True, "content": {
    "application/json": {"schema": TrackerBatch.model_json_schema()}}}})
async def ingest_poses(request: Request, _: AgentToken, testbed: TestbedDep) -> dict:
    """A batch of tracker poses ``[t, x, y, theta]`` of one robot (agent or admin token).

    Body: :class:`TrackerBatch`.  Rows that are not four finite numbers are
    refused and counted in ``rejected``; the others are kept.  A robot the
    testbed does not know is refused (404): it must register first.
    """
    raw = await request.body()

    def work() -> dict:
        robot_id, poses, received = _parse_batch(raw)
        if robot_id not in testbed.scheduler.robots:
            raise HTTPException(404, f"Unknown robot {robot_id!r}: register it with POST /api/v1/robots first")
        stored, run_id = testbed.router.ingest(robot_id, poses)
        return {"received": received, "accepted": len(poses), "rejected": received - len(poses),
                "stored": stored, "run_id": run_id}

    return await anyio.to_thread.run_sync(work)


def _parse_batch(raw: bytes) -> tuple[str, np.ndarray, int]:
    """``robot_id``, the valid rows and the number of rows of a tracker batch; 422 naming what is wrong."""
    try:
        doc = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise HTTPException(422, f"body is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise HTTPException(422, "body must be a JSON object {robot_id, poses}")
    robot_id, poses = doc.get("robot_id"), doc.get("poses")
    if not isinstance(robot_id, str) or not 1 <= len(robot_id) <= 64:
        raise HTTPException(422, "robot_id: must be a string of 1 to 64 characters")
    if not isinstance(poses, list):
        raise HTTPException(422, "poses: must be a list of [t, x, y, theta] rows")
    if len(poses) > 100_000:
        raise HTTPException(422, "poses: at most 100000 rows per batch")
    try:
        arr = np.array(poses, dtype=float)
        ok = arr.ndim == 2 and arr.shape[1] == 4
    except (ValueError, TypeError):
        ok = False
    if not ok:  # ragged or non-numeric rows: keep the good ones, row by row (the slow path)
        good = [r for r in poses if isinstance(r, list) and len(r) == 4
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)]
        arr = np.array(good, dtype=float).reshape(-1, 4)
    return robot_id, arr[np.isfinite(arr).all(axis=1)], len(poses)
