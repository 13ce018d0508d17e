"""Live event stream (server-sent events) of state changes and robot poses."""

from __future__ import annotations

from typing import Any, Optional

from fastapi import APIRouter, Request
from fastapi.responses import StreamingResponse

from ...access import event_for
from ..deps import CurrentUser, TestbedDep
from ..responses import AUTHENTICATED

router = APIRouter(tags=["events"], responses=AUTHENTICATED)


class EventStream(StreamingResponse):
    """A server-sent event stream (documented as ``text/event-stream``, not JSON)."""

    media_type = "text/event-stream"


STREAM_DOC = {200: {"description": "Server-sent events, never ending: `event: <kind>` and `data: <JSON object>` "
                                   "lines, an event a blank line apart.",
                    "content": {"text/event-stream": {"schema": {"type": "string"}}}}}


@router.get("/events", response_class=EventStream, responses=STREAM_DOC)
async def events(request: Request, user: CurrentUser, testbed: TestbedDep) -> EventStream:
    """Server-sent events: ``experiment``, ``run``, ``subfield``, ``robot`` and ``pose`` (JSON data).

    You receive your own experiments' and runs' events, the sub-fields, and
    the live positions of robots that run no run or yours (admins receive
    everything).  Poses are in field coordinates.
    """

    def view(ev: dict[str, Any]) -> Optional[dict[str, Any]]:
        return event_for(user, ev)

    async def stream():  # type: ignore[no-untyped-def]
        async for chunk in testbed.broker.stream(view):
            if await request.is_disconnected():
                break
            yield chunk

    return EventStream(stream(), headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
