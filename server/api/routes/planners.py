"""Planners the testbed offers: built-ins and installed plug-ins, and the plug-ins that fail to load."""

from __future__ import annotations

from fastapi import APIRouter

from ...schemas import FLEET_PLANNER, PlannerPublic, PluginPage
from ..deps import CurrentUser
from ..responses import AUTHENTICATED

router = APIRouter(prefix="/planners", tags=["planners"], responses=AUTHENTICATED)


@router.get("", response_model=PluginPage[PlannerPublic], response_model_exclude_unset=True)
def list_planners(_: CurrentUser) -> PluginPage[PlannerPublic]:
    """Every selectable planner: name, description, parameter defaults (null: any parameters), its
    ``parameters`` (name, type, unit, default, range, description; null: any) and whether it plans
    multi-robot jobs only (``fleet_only``: ``prioritized`` and ``lacam``; any other plans each robot alone).
    ``load_errors``: each installed plug-in planner that does not load (name, kind, source, error_type,
    message, distribution); it is not in ``data``."""
    from contract.parameters import defaults_of
    from planners import get_planner
    from planners import lacam
    from planners.prioritized import DESCRIPTION, EXECUTION_PARAM, fleet_defaults, fleet_parameters
    from planners.registry import PLUGINS, available_planners

    errors = PLUGINS.load_errors()  # every plug-in is tried: the others are loaded now
    plugins = set(PLUGINS.names())
    out = []
    for name in available_planners():
        if name in plugins and PLUGINS.loaded(name) is None:
            continue  # it failed to load: in load_errors
        p = get_planner(name)
        params = None if p.parameters is None else [q.to_dict() for q in p.parameters]
        out.append({"name": name, "description": p.description, "defaults": defaults_of(p.parameters),
                    "parameters": params, "fleet_only": False})
    out.append({"name": FLEET_PLANNER, "description": DESCRIPTION, "defaults": fleet_defaults(),
                "parameters": [q.to_dict() for q in (*fleet_parameters(), EXECUTION_PARAM)], "fleet_only": True})
    out.append({"name": lacam.NAME, "description": lacam.DESCRIPTION, "defaults": lacam.lacam_defaults(),
                "parameters": [q.to_dict() for q in lacam.lacam_parameters()], "fleet_only": True})
    return PluginPage[PlannerPublic].model_validate(
        {"data": out, "count": len(out), "load_errors": [e.to_dict() for e in errors]})
