"""Where a field robot stands when it (re)joins the testbed: asked of its tracker, not remembered.

After a restart the server knows nothing of where the robots are; the last
session's logged poses are history, not the field.  When a field robot
registers or answers again, :class:`Locator` subscribes to its localisation
once (``T,T,O,1,free``: the tracker's newest frame comes at once, moving or
standing; docs/protocol.md) and hands the pose to the tracker as the robot's
last known pose (:meth:`server.tracking.PoseRouter.place`), which the API and
the dashboard show.
"""

from __future__ import annotations

import asyncio
import logging
import math
from typing import Callable, Optional

from .agent_link import AgentLink
from .errors import AgentRefused, AgentUnavailable

__all__ = ["Locator", "tracked_pose"]

log = logging.getLogger("twb.server")


async def tracked_pose(host: str, port: int, *, control_key: Optional[str] = None,
                       timeout_s: float = 5.0) -> Optional[tuple[float, float, float, float]]:
    """The robot's pose as its tracker sees it now, ``(t s, x m, y m, theta rad)`` in the robot's frame: the
    first ``PO`` line after ``T,T,O,1,free``; None when the robot does not answer within ``timeout_s``."""
    loop = asyncio.get_running_loop()
    first: asyncio.Future[tuple[str, ...]] = loop.create_future()
    try:
        link = await AgentLink.connect(host, port, time_scale=1.0, on_line=lambda *a: None,
                                       control_key=control_key, timeout_s=timeout_s)
    except (AgentUnavailable, AgentRefused):
        return None
    async with link:
        link.on_pose = lambda _line, fields: first.done() or first.set_result(fields)
        try:
            await link.request("T,T,O,1,free", timeout_s)
            fields = await asyncio.wait_for(first, timeout_s)
            await link.request("T,T,O,0", timeout_s)
        except (AgentUnavailable, AgentRefused, asyncio.TimeoutError):
            return None
    try:
        x, y, a, t = (float(f) for f in fields[:4])
    except ValueError:
        return None
    pose = (t, x / 1000.0, y / 1000.0, math.radians(a))
    return pose if all(math.isfinite(v) for v in pose) else None


class Locator:
    """Looks up where field robots stand when they join; ``place(robot_id, pose)`` receives each answer
    (robot frame, as :func:`tracked_pose` gives it)."""

    def __init__(self, place: Callable[[str, tuple[float, float, float, float]], None]) -> None:
        self._place = place
        self._tasks: set[asyncio.Task] = set()

    def locate(self, robot_id: str, host: str, port: int, control_key: Optional[str]) -> None:
        """Ask ``robot_id``'s tracker where it is, in the background (on the event loop)."""
        task = asyncio.get_running_loop().create_task(self._locate(robot_id, host, port, control_key),
                                                      name=f"twb-locate-{robot_id}")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _locate(self, robot_id: str, host: str, port: int, control_key: Optional[str]) -> None:
        pose = await tracked_pose(host, port, control_key=control_key)
        if pose is None:
            log.info("robot %s: its tracker gave no pose; the field view leaves it out until it moves", robot_id)
            return
        self._place(robot_id, pose)

    async def stop(self) -> None:
        """Cancel the lookups under way."""
        for task in list(self._tasks):
            task.cancel()
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)
