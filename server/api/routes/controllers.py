"""Path-tracking controllers the robots offer: built-ins and installed plug-ins (docs/controllers.md), and the
plug-ins that fail to load."""

from __future__ import annotations

from fastapi import APIRouter

from ...schemas import ControllerPublic, PluginPage
from ..deps import CurrentUser
from ..responses import AUTHENTICATED

router = APIRouter(prefix="/controllers", tags=["controllers"], responses=AUTHENTICATED)


@router.get("", response_model=PluginPage[ControllerPublic], response_model_exclude_unset=True)
def list_controllers(_: CurrentUser) -> PluginPage[ControllerPublic]:
    """Every selectable controller: name, description, source, whether it runs compiled, and its parameters
    (name, type, unit, default, range [low, high], description; SI units).  ``load_errors``: each installed
    plug-in controller that does not load (name, kind, source, error_type, message, distribution); it is not
    in ``data``."""
    from contract.controller_specs import PLUGINS, available_controllers, controller_spec

    errors = PLUGINS.load_errors()  # every plug-in is tried: the others are loaded now
    plugins = set(PLUGINS.names())
    out = [controller_spec(name).to_dict() for name in available_controllers()
           if name not in plugins or PLUGINS.loaded(name) is not None]
    return PluginPage[ControllerPublic].model_validate(
        {"data": out, "count": len(out), "load_errors": [e.to_dict() for e in errors]})
