"""Live event stream (server-sent events) of state changes and robot poses."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import StreamingResponse

from ..deps import CurrentUser, TestbedDep
from ..responses import AUTHENTICATED

router = APIRouter(tags=["events"], responses=AUTHENTICATED)


@router.get("/events")
async def events(request: Request, user: CurrentUser, testbed: TestbedDep) -> StreamingResponse:
    """Server-sent events: ``experiment``, ``run``, ``subfield``, ``robot`` and ``pose`` (JSON data).

    You receive your own experiments' and runs' events and every robot's live
    position (admins receive everything).  Poses are in field coordinates.
    """
    uid, admin = user.id, user.is_admin

    def accept(ev: dict[str, Any]) -> bool:
        owner = ev.get("owner_id")
        if ev["type"] in ("experiment", "run"):
            return admin or owner == uid
        return True

    async def stream():  # type: ignore[no-untyped-def]
        async for chunk in testbed.broker.stream(accept):
            if await request.is_disconnected():
                break
            yield chunk

    return StreamingResponse(stream(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
