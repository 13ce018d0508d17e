"""Planners the testbed offers: built-ins and installed plug-ins."""

from __future__ import annotations

from fastapi import APIRouter

from ..deps import CurrentUser
from ..responses import AUTHENTICATED

router = APIRouter(prefix="/planners", tags=["planners"], responses=AUTHENTICATED)


@router.get("")
def list_planners(_: CurrentUser) -> dict:
    """Every selectable planner: name, description and parameter defaults (null: any parameters)."""
    from planners import get_planner
    from planners.registry import available_planners

    out = []
    for name in available_planners():
        try:
            p = get_planner(name)
        except Exception:  # noqa: BLE001 - a broken plug-in is left out, not an error for everyone
            continue
        out.append({"name": name, "description": p.description,
                    "defaults": dict(p.defaults) if p.defaults is not None else None})
    return {"data": out, "count": len(out)}
