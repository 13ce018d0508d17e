"""Planners the testbed offers: built-ins and installed plug-ins."""

from __future__ import annotations

from fastapi import APIRouter

from ...schemas import FLEET_PLANNER, Page, PlannerPublic
from ..deps import CurrentUser
from ..responses import AUTHENTICATED

router = APIRouter(prefix="/planners", tags=["planners"], responses=AUTHENTICATED)


@router.get("", response_model=Page[PlannerPublic])
def list_planners(_: CurrentUser) -> Page[PlannerPublic]:
    """Every selectable planner: name, description, parameter defaults (null: any parameters) and whether it
    plans multi-robot jobs only (``fleet_only``: ``prioritized``; any other plans each robot alone)."""
    from planners import get_planner
    from planners.prioritized import DESCRIPTION, fleet_defaults
    from planners.registry import available_planners

    out = []
    for name in available_planners():
        try:
            p = get_planner(name)
        except Exception:  # noqa: BLE001 - a broken plug-in is left out, not an error for everyone
            continue
        out.append(PlannerPublic(name=name, description=p.description,
                                 defaults=dict(p.defaults) if p.defaults is not None else None, fleet_only=False))
    out.append(PlannerPublic(name=FLEET_PLANNER, description=DESCRIPTION, defaults=fleet_defaults(), fleet_only=True))
    return Page(data=out, count=len(out))
