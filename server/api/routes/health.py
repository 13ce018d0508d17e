"""``GET /health``: open liveness check."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request

from ...schemas import HealthPublic
from ..deps import TestbedDep, authenticate, bearer_token

router = APIRouter(tags=["health"])


@router.get("/health", response_model=HealthPublic, response_model_exclude_unset=True)
async def health(request: Request, testbed: TestbedDep) -> HealthPublic:
    """Liveness (no token needed); with a valid token also the queue and the fleet."""
    token = bearer_token(request)
    if token:
        try:
            await authenticate(request, token)
        except HTTPException:
            token = None
    return HealthPublic(status="ok", version="1", **(testbed.dispatcher.summary() if token else {}))
