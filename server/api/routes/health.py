"""``GET /health``: open liveness check."""

from __future__ import annotations

from fastapi import APIRouter

from ..deps import TestbedDep

router = APIRouter(tags=["health"])


@router.get("/health")
async def health(testbed: TestbedDep) -> dict:
    """Liveness and a summary of the testbed (no token needed)."""
    return {"status": "ok", "version": "1", **testbed.dispatcher.summary()}
