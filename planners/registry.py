"""Planner registry: the built-ins plus plug-ins from the ``teleworkbench.planners`` entry points.

A plug-in distribution declares, in its ``pyproject.toml``::

    [project.entry-points."teleworkbench.planners"]
    straight = "my_package.planners:StraightLine"

The object may be a :class:`~planners.base.Planner` subclass or instance, or
a plain function ``f(space, start, goal, params, seed) -> (N, 2) array``.
Built-in names cannot be taken over by plug-ins.  Loading (and keeping load
errors as data) is :class:`contract.plugins.PluginRegistry`'s, shared with the
controllers.
"""

from __future__ import annotations

import inspect
from typing import Any, Callable

from contract.plugins import RESTART_HINT, LoadError, PluginRegistry, PluginStatus

from .anyangle import ThetaStarPlanner
from .astar import AStarPlanner
from .base import Planner
from .errors import UnknownPlanner
from .fm2 import FM2Planner
from .fmm import FMMPlanner
from .ompl_planners import ompl_builtins
from .prm import PRMPlanner
from .st_astar import SpaceTimeAStar

__all__ = ["ENTRY_POINT_GROUP", "PLUGINS", "RESTART_HINT", "LoadError", "PluginStatus", "available_planners",
           "get_planner", "plugin_report", "register_planner", "unregister_planner"]

ENTRY_POINT_GROUP = "teleworkbench.planners"
_BUILTINS: dict[str, type[Planner]] = {
    "fmm": FMMPlanner,
    "fm2": FM2Planner,
    "prm": PRMPlanner,
    "astar": AStarPlanner,
    "st_astar": SpaceTimeAStar,
    "theta_star": ThetaStarPlanner,
    **ompl_builtins(),  # OMPL's planners: listed always, usable with the ompl extra
}
_builtin_instances: dict[str, Planner] = {}


class FunctionPlanner(Planner):
    """Adapts a plain function ``f(space, start, goal, params, seed)`` to the interface."""

    parameters = None

    def __init__(self, name: str, fn: Callable[..., Any]) -> None:
        self.name = name
        self.description = (inspect.getdoc(fn) or "").split("\n")[0]
        self.stochastic = bool(getattr(fn, "stochastic", False))  # a function declares it as an attribute
        self._fn = fn

    def solve(self, space, start, goal, params, seed):  # type: ignore[no-untyped-def]
        return self._fn(space, start, goal, params, seed)


def _adapt(name: str, obj: Any, source: str) -> Planner:
    """A created, configured plug-in object (from ``source``) as a :class:`Planner` named ``name``; TypeError
    if it is none."""
    if isinstance(obj, Planner):
        if not obj.name:
            obj.name = name
        return obj
    if callable(obj):
        return FunctionPlanner(name, obj)
    raise TypeError(f"planner {name!r} ({source}) must be a Planner subclass, a Planner instance or a function")


#: the plug-in planners of this process
PLUGINS: PluginRegistry[Planner] = PluginRegistry("planner", ENTRY_POINT_GROUP, adapt=_adapt, refuse=UnknownPlanner,
                                                  reserved=_BUILTINS)


def register_planner(name: str, planner: Any) -> Planner:
    """Register ``planner`` (class, instance or function) under ``name`` for this process."""
    return PLUGINS.register(name, planner)


def unregister_planner(name: str) -> None:
    """Drop the plug-in planner ``name`` of this process (its ``cleanup`` runs); nothing if it is not loaded."""
    PLUGINS.unregister(name)


def available_planners() -> dict[str, str]:
    """Every selectable planner name with its one-line description (plug-ins load lazily)."""
    out = {name: cls.description for name, cls in _BUILTINS.items()}
    eps = PLUGINS.entry_points()
    for name in PLUGINS.names():
        loaded = PLUGINS.loaded(name)
        out[name] = (loaded.description or "registered planner") if loaded is not None else f"plug-in {eps[name].value}"
    return out


def get_planner(name: str) -> Planner:
    """The planner called ``name``; :class:`UnknownPlanner` listing the choices if none, or saying why a
    plug-in failed to load (its :class:`~contract.plugins.LoadError` as ``load_error``)."""
    if name in _BUILTINS:
        if name not in _builtin_instances:
            _builtin_instances[name] = _BUILTINS[name]()
        return _builtin_instances[name]
    planner = PLUGINS.get(name)
    if planner is None:
        raise UnknownPlanner(f"unknown planner {name!r} (available: {', '.join(available_planners())})")
    return planner


def plugin_report() -> list[PluginStatus]:
    """Every installed plug-in planner, loaded now (or tried): what ``twb plugins list`` shows.

    Entry points that use a built-in's name are listed as refused.
    """
    return PLUGINS.report()
