"""HTTP link from an agent to the testbed server: robot registration and tracker pose batches.

The contract (see ``docs/protocol.md``), both with ``Authorization: Bearer <token>``:

- ``POST {server}/api/v1/robots`` with ``{"robot_id", "host", "port",
  "platform", "backend", "profile", "origin": [x0, y0], "area": [w, h]}``
  once per robot at start-up;
- ``POST {server}/api/v1/tracker/poses`` with ``{"robot_id": str,
  "poses": [[t, x, y, theta], ...]}`` per batch.

Any 2xx answer is success.  Network errors, timeouts, 5xx, 408 and 429 are
retried with exponential back-off (0.5 s doubling to 30 s); other 4xx answers
are logged and the request dropped (retrying a refused request cannot help).
Nothing here ever raises into the agent: a server that is down only costs
log lines and, past ``max_pending_poses``, the oldest pose batches.
"""

from __future__ import annotations

import asyncio
import collections
import logging
from typing import Any

import httpx
import numpy as np

__all__ = ["ServerLink"]

log = logging.getLogger("robot_agent.host.server_link")

_RETRY_STATUS = {408, 429}


class ServerLink:
    """Posts registrations and tracker batches to ``server_url`` with ``token``
    (a :class:`~robot_agent.host.sinks.TrackerSink`)."""

    def __init__(self, server_url: str, token: str, *, timeout_s: float = 5.0, retry_initial_s: float = 0.5,
                 retry_max_s: float = 30.0, max_batch_poses: int = 5000, max_pending_poses: int = 1_000_000,
                 transport: httpx.AsyncBaseTransport | None = None) -> None:
        self.base = server_url.rstrip("/")
        self._client = httpx.AsyncClient(
            headers={"Authorization": f"Bearer {token}"}, timeout=timeout_s, transport=transport
        )
        self.retry_initial_s, self.retry_max_s = retry_initial_s, retry_max_s
        self.max_batch_poses, self.max_pending_poses = max_batch_poses, max_pending_poses
        self._queue: collections.deque[tuple[str, dict[str, Any]]] = collections.deque()
        self._pending_poses = 0
        self._dropped_poses = 0
        self._wake = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self._task: asyncio.Task[None] | None = None
        self._closed = False
        self.registered: set[str] = set()  #: robot ids the server accepted

    # ------------------------------------------------------------------ public

    def register(self, info: dict[str, Any]) -> None:
        """Queue the registration of one robot (retried until the server answers)."""
        self._enqueue("/api/v1/robots", info)

    async def send(self, robot_id: str, poses: np.ndarray) -> None:
        """Queue ``poses`` ``(M, 4)`` of ``robot_id`` for posting (never blocks)."""
        rows = np.asarray(poses, dtype=float)
        for start in range(0, len(rows), self.max_batch_poses):
            chunk = rows[start : start + self.max_batch_poses]
            self._pending_poses += len(chunk)
            self._enqueue("/api/v1/tracker/poses", {"robot_id": robot_id, "poses": chunk.tolist()})
        self._shed()

    async def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until everything queued was delivered or dropped; False on timeout."""
        try:
            await asyncio.wait_for(self._idle.wait(), timeout_s)
            return True
        except asyncio.TimeoutError:
            return False

    async def aclose(self, timeout_s: float = 1.0) -> None:
        """Deliver what is pending for up to ``timeout_s``, then stop and close the client."""
        if self._closed:
            return
        if self._queue:
            if not await self.flush(timeout_s):
                log.warning("server %s: %d requests undelivered at shutdown", self.base, len(self._queue))
        self._closed = True
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
        await self._client.aclose()

    # ------------------------------------------------------------------ worker

    def _enqueue(self, path: str, body: dict[str, Any]) -> None:
        if self._closed:
            return
        self._queue.append((path, body))
        self._idle.clear()
        self._wake.set()
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._worker(), name="twb-server-link")

    def _shed(self) -> None:
        """Drop the oldest pose batches while more than ``max_pending_poses`` wait."""
        while self._pending_poses > self.max_pending_poses:
            for i, (path, body) in enumerate(self._queue):
                if "poses" in body:
                    del self._queue[i]
                    self._pending_poses -= len(body["poses"])
                    self._dropped_poses += len(body["poses"])
                    break
            else:
                break
        if self._dropped_poses:
            log.warning("server %s unreachable: dropped %d tracker poses so far", self.base, self._dropped_poses)

    async def _post(self, path: str, body: dict[str, Any]) -> bool | None:
        """True: delivered; False: refused for good; None: retry later."""
        try:
            r = await self._client.post(self.base + path, json=body)
        except httpx.HTTPError as exc:
            log.warning("POST %s%s failed: %s: %s (will retry)", self.base, path, type(exc).__name__, exc)
            return None
        if r.is_success:
            return True
        if r.status_code >= 500 or r.status_code in _RETRY_STATUS:
            log.warning("POST %s%s: HTTP %d (will retry)", self.base, path, r.status_code)
            return None
        log.error("POST %s%s refused: HTTP %d %s (dropped)", self.base, path, r.status_code, r.text[:200])
        return False

    async def _worker(self) -> None:
        delay = self.retry_initial_s
        while True:
            if not self._queue:
                self._idle.set()
                self._wake.clear()
                await self._wake.wait()
                continue
            path, body = self._queue[0]
            ok = await self._post(path, body)
            if ok is None:
                await asyncio.sleep(delay)
                delay = min(delay * 2, self.retry_max_s)
                continue
            delay = self.retry_initial_s
            if self._queue and self._queue[0][1] is body:
                self._queue.popleft()
                if "poses" in body:
                    self._pending_poses -= len(body["poses"])
                elif ok:
                    self.registered.add(str(body.get("robot_id")))
                    log.info("registered robot %s with %s", body.get("robot_id"), self.base)
