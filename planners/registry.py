"""Planner registry: the built-ins plus plug-ins from the ``teleworkbench.planners`` entry points.

A plug-in distribution declares, in its ``pyproject.toml``::

    [project.entry-points."teleworkbench.planners"]
    straight = "my_package.planners:StraightLine"

The object may be a :class:`~planners.base.Planner` subclass or instance, or
a plain function ``f(space, start, goal, params, seed) -> (N, 2) array``.
Built-in names cannot be taken over by plug-ins.
"""

from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Callable, Optional

from .astar import AStarPlanner
from .base import Planner
from .errors import UnknownPlanner
from .fm2 import FM2Planner
from .fmm import FMMPlanner
from .prm import PRMPlanner
from .st_astar import SpaceTimeAStar

__all__ = ["ENTRY_POINT_GROUP", "RESTART_HINT", "PluginStatus", "available_planners", "get_planner", "plugin_report",
           "register_planner"]

ENTRY_POINT_GROUP = "teleworkbench.planners"
#: what a plug-in that fails to load needs most often: a process started before it was installed
RESTART_HINT = ("if you installed it while the testbed was running, restart the testbed (stop `twb up` or "
                "`twb server` and start it again) so that its processes see the new package")
_BUILTINS: dict[str, type[Planner]] = {
    "fmm": FMMPlanner,
    "fm2": FM2Planner,
    "prm": PRMPlanner,
    "astar": AStarPlanner,
    "st_astar": SpaceTimeAStar,
}
_instances: dict[str, Planner] = {}


class FunctionPlanner(Planner):
    """Adapts a plain function ``f(space, start, goal, params, seed)`` to the interface."""

    defaults = None

    def __init__(self, name: str, fn: Callable[..., Any]) -> None:
        self.name = name
        self.description = (inspect.getdoc(fn) or "").split("\n")[0]
        self.stochastic = bool(getattr(fn, "stochastic", False))  # a function declares it as an attribute
        self._fn = fn

    def solve(self, space, start, goal, params, seed):  # type: ignore[no-untyped-def]
        return self._fn(space, start, goal, params, seed)


def _adapt(name: str, obj: Any) -> Planner:
    if isinstance(obj, type) and issubclass(obj, Planner):
        obj = obj()
    if isinstance(obj, Planner):
        if not obj.name:
            obj.name = name
        return obj
    if callable(obj):
        return FunctionPlanner(name, obj)
    raise TypeError(f"planner {name!r} must be a Planner subclass, a Planner instance or a function")


def register_planner(name: str, planner: Any) -> Planner:
    """Register ``planner`` (class, instance or function) under ``name`` for this process."""
    if name in _BUILTINS:
        raise ValueError(f"{name!r} is a built-in planner and cannot be replaced")
    _instances[name] = _adapt(name, planner)
    return _instances[name]


def _plugin_entry_points() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name not in _BUILTINS}


def available_planners() -> dict[str, str]:
    """Every selectable planner name with its one-line description (plug-ins load lazily)."""
    out = {name: cls.description for name, cls in _BUILTINS.items()}
    for name, ep in sorted(_plugin_entry_points().items()):
        out[name] = f"plug-in {ep.value}"
    for name, inst in _instances.items():
        out.setdefault(name, inst.description or "registered planner")
    return out


def get_planner(name: str) -> Planner:
    """The planner registered as ``name``; :class:`UnknownPlanner` listing the choices if none."""
    if name in _instances:
        return _instances[name]
    if name in _BUILTINS:
        _instances[name] = _BUILTINS[name]()
        return _instances[name]
    eps = _plugin_entry_points()
    if name not in eps:
        raise UnknownPlanner(f"unknown planner {name!r} (available: {', '.join(available_planners())})")
    _instances[name] = _load_plugin(name, eps[name])
    return _instances[name]


def _load_plugin(name: str, ep: EntryPoint) -> Planner:
    """Import a plug-in's entry point and adapt it; :class:`UnknownPlanner` saying why it failed."""
    importlib.invalidate_caches()  # a package installed after this process started is found
    try:
        return _adapt(name, ep.load())
    except Exception as exc:  # a broken plug-in must not take the testbed down
        raise UnknownPlanner(f"plug-in planner {name!r} ({ep.value}) failed to load: {exc} ({RESTART_HINT})") from exc


@dataclass(frozen=True)
class PluginStatus:
    """One plug-in entry point: its ``name``, ``target`` (``module:object``), the distribution that
    declares it (``"name version"``), whether it loads, and why not (``error``)."""

    name: str
    target: str
    distribution: str
    loaded: bool
    error: str = ""


def plugin_report() -> list[PluginStatus]:
    """Every installed plug-in planner, loaded now (or tried): what ``twb plugins list`` shows.

    Entry points that use a built-in's name are listed as refused.
    """
    out = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        dist = _distribution(ep)
        if ep.name in _BUILTINS:
            out.append(PluginStatus(ep.name, ep.value, dist, False, "a built-in planner has this name"))
            continue
        try:
            _instances[ep.name] = _instances.get(ep.name) or _load_plugin(ep.name, ep)
            out.append(PluginStatus(ep.name, ep.value, dist, True))
        except UnknownPlanner as exc:
            reason = str(exc).split(" failed to load: ", 1)[-1]
            out.append(PluginStatus(ep.name, ep.value, dist, False, reason))
    return out


def _distribution(ep: EntryPoint) -> str:
    dist: Optional[Any] = getattr(ep, "dist", None)
    if dist is None:
        return ""
    return f"{dist.metadata['Name']} {dist.version}"
