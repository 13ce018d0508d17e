"""``GET /health``: open liveness check."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request

from ...schemas import HealthPublic
from ..deps import TestbedDep, authenticate, bearer_token

router = APIRouter(tags=["health"])


@router.get("/health", response_model=HealthPublic, response_model_exclude_unset=True)
async def health(request: Request, testbed: TestbedDep) -> HealthPublic:
    """Liveness (no token needed; ``degraded`` while the compute pool's fresh workers cannot run a job); with a
    valid token also the queue, the fleet and the compute pool."""
    compute = testbed.pool.status()
    status = "degraded" if compute["restarts"] and not compute["ready"] else "ok"
    token = bearer_token(request)
    if token:
        try:
            await authenticate(request, token)
        except HTTPException:
            token = None
    extra = {**testbed.dispatcher.summary(), "compute": compute} if token else {}
    return HealthPublic(status=status, version="1", **extra)
