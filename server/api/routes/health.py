"""``GET /health``: open liveness check."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request

from ..deps import TestbedDep, authenticate, bearer_token

router = APIRouter(tags=["health"])


@router.get("/health")
async def health(request: Request, testbed: TestbedDep) -> dict:
    """Liveness (no token needed; ``degraded`` while the compute pool's fresh workers cannot run a job); with a
    valid token also the queue, the fleet and the compute pool."""
    compute = testbed.pool.status()
    out: dict = {"status": "degraded" if compute["restarts"] and not compute["ready"] else "ok", "version": "1"}
    token = bearer_token(request)
    if token:
        try:
            await authenticate(request, token)
        except HTTPException:
            return out
        out.update(testbed.dispatcher.summary())
        out["compute"] = compute
    return out
