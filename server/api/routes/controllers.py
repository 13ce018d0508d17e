"""Path-tracking controllers the robots offer: built-ins and installed plug-ins (docs/controllers.md)."""

from __future__ import annotations

from fastapi import APIRouter

from ...schemas import ControllerPublic, Page
from ..deps import CurrentUser
from ..responses import AUTHENTICATED

router = APIRouter(prefix="/controllers", tags=["controllers"], responses=AUTHENTICATED)


@router.get("", response_model=Page[ControllerPublic], response_model_exclude_unset=True)
def list_controllers(_: CurrentUser) -> Page[ControllerPublic]:
    """Every selectable controller: name, description, source, whether it runs compiled, and its parameters
    (name, unit, default, range [low, high], description; SI units)."""
    from contract.controller_specs import ControllerError, available_controllers, controller_spec

    out = []
    for name in available_controllers():
        try:
            out.append(controller_spec(name).to_dict())
        except ControllerError:  # a broken plug-in is left out, not an error for everyone
            continue
    return Page[ControllerPublic].model_validate({"data": out, "count": len(out)})
