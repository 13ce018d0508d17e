"""Which path-tracking controllers a robot can run, their parameters, and plug-ins.

The built-ins run inside the compiled simulation core
(:mod:`robot_agent.engine.controllers`, dispatched by :attr:`ControllerSpec.cid`
with a row of :data:`~robot_agent.engine.controllers.PARAM_SLOTS` parameters).  A
plug-in distribution adds controllers that run in Python, declared in its
``pyproject.toml`` as planners are (:mod:`planners.registry`)::

    [project.entry-points."teleworkbench.controllers"]
    wiggle = "my_package.controllers:Wiggle"

The object (a class is instantiated, then configured: :class:`Controller`,
a :class:`contract.plugins.Plugin`, is the interface) has ``parameters`` (a
sequence of :class:`~contract.parameters.Param` of type ``number`` or
``integer``, at most 8, may be empty; ``params`` is the older name), an
optional ``description`` and ``source``, and
``command(pose, path, progress, params, dt) -> (v, w)``: the body velocities
(m/s, rad/s) for the believed ``pose`` (x, y, theta), the path ``(P, 3)``,
``progress`` (the segment and fraction of the robot's projection on the
path), the validated ``params`` dict and the control step ``dt`` (s).  The
follower's arrival, alignment, stall, timeout and limits apply as for the
built-ins.  Built-in names cannot be taken over.  Loading, and keeping load
errors as data, is :class:`contract.plugins.PluginRegistry`'s, shared with the
planners.  Everything here is plain Python (no numba): the server and the
sandbox import it cheaply.

Parameters with ``compiled=False`` (regulated pure pursuit's ``replan*``) are
not in the compiled row: the agent reads them in Python
(:mod:`robot_agent.engine.replan`), so the kernels and their numbers stay as they were.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional, Sequence

import numpy as np

from .parameters import Param, ParamError, check_values
from .plugins import LoadError, Plugin, PluginRegistry, PluginStatus

__all__ = ["BUILTINS", "DEFAULT_CONTROLLER", "ENTRY_POINT_GROUP", "PLUGINS", "REPLAN_PARAMS", "Controller",
           "ControllerError", "ControllerSpec", "LoadError", "Param", "PluginController", "PluginStatus", "Selection",
           "available_controllers", "controller_report", "controller_spec", "register_controller",
           "unregister_controller", "select"]

ENTRY_POINT_GROUP = "teleworkbench.controllers"
DEFAULT_CONTROLLER = "schema"
_SLOTS = 8  # robot_agent.engine.controllers.PARAM_SLOTS (not imported: that module compiles)
_PLUGIN_ID = 100  # robot_agent.engine.controllers.PLUGIN


class ControllerError(ValueError):
    """An unknown controller or a bad parameter; ``field`` names what is wrong (``controller`` or
    ``controller_params.<name>``)."""

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(message)
        self.field = field_name


#: replanning (robot_agent.engine.replan): off by default, so every run without it stays as it was
REPLAN_PARAMS = (
    Param("replan", "0|1", 0, 0, 1, "1: check the path ahead 5 times a second and, when a moving obstacle "
          "(where it will be) or another robot (where it is) blocks it, replan to the goal with st_astar "
          "around the obstacles' known trajectories", type="integer", compiled=False),
    Param("replan_horizon_s", "s", 3.0, 0.5, 30.0, "how far ahead the check looks, in seconds of driving at "
          "speed_m_s", compiled=False),
    Param("replan_min_interval_s", "s", 1.0, 0.2, 60.0, "at least this long between two replans",
          compiled=False),
)


@dataclass(frozen=True)
class ControllerSpec:
    """A selectable controller: its ``name``, compiled id ``cid`` (plug-ins: 100), parameters, a one-line
    ``description`` and the literature ``source``; ``plugin`` is the loaded plug-in object, if one."""

    name: str
    cid: int
    description: str
    source: str
    params: tuple[Param, ...] = ()
    plugin: Any = field(default=None, compare=False)

    @property
    def compiled(self) -> bool:
        """Whether it runs inside the compiled core (built-ins) or in Python (plug-ins)."""
        return self.plugin is None

    def to_dict(self) -> dict[str, Any]:
        """JSON form (what ``GET /api/v1/controllers`` lists)."""
        return {"name": self.name, "description": self.description, "source": self.source,
                "compiled": self.compiled, "parameters": [p.to_dict() for p in self.params]}


BUILTINS: dict[str, ControllerSpec] = {s.name: s for s in (
    ControllerSpec("schema", 0, "motor-schema P-controller: move-to-waypoint schema and a heading P-control "
                   "(the default; its gains are the robot profile's)", "Arkin 1989; the Teleworkbench robots",
                   REPLAN_PARAMS),
    ControllerSpec("pure_pursuit", 1, "pure pursuit: the arc through the path point a fixed lookahead ahead",
                   "Coulter 1992, CMU-RI-TR-92-01", (
                       Param("lookahead_m", "m", 0.06, 0.02, 1.0, "arc length from the robot's projection on the "
                             "path to the pursued point"),
                       Param("speed_m_s", "m/s", 0.2, 0.01, 1.0, "cruise speed (at most the robot's top speed)"),
                       Param("rotate_to_heading_rad", "rad", 1.2, 0.1, math.pi,
                             "turn on the spot while the pursued point lies further off the heading"),
                       *REPLAN_PARAMS)),
    ControllerSpec("regulated_pure_pursuit", 2, "regulated pure pursuit (nav2): speed-scaled lookahead, slower "
                   "in curves, near obstacles and on the approach to the goal",
                   "Macenski, Singh, Martin, Gines 2023, Autonomous Robots (arXiv:2305.20026)", (
                       Param("speed_m_s", "m/s", 0.2, 0.01, 1.0, "desired speed (at most the robot's top speed)"),
                       Param("lookahead_time_s", "s", 0.4, 0.0, 10.0, "lookahead = speed x this time ..."),
                       Param("min_lookahead_m", "m", 0.05, 0.02, 1.0, "... at least this ..."),
                       Param("max_lookahead_m", "m", 0.1, 0.02, 2.0, "... and at most this"),
                       Param("min_radius_m", "m", 0.25, 0.0, 5.0, "curves of a smaller radius scale the speed by "
                             "radius / min_radius_m (0: no curvature regulation)"),
                       Param("proximity_m", "m", 0.04, 0.0, 1.0, "closer to a block, wall, moving obstacle or robot than this (robot edge) "
                             "scales the speed by distance / proximity_m (0: no proximity regulation)"),
                       Param("approach_m", "m", 0.15, 0.0, 1.0, "within this of the goal the speed scales by "
                             "distance / approach_m"),
                       Param("min_speed_m_s", "m/s", 0.03, 0.0, 0.5, "floor of the regulated speed"),
                       *REPLAN_PARAMS)),
    ControllerSpec("kanayama", 3, "Kanayama's trajectory tracking: a reference pose moves along the path; "
                   "feedback on its error in the robot frame",
                   "Kanayama, Kimura, Miyazaki, Noguchi 1990, ICRA, 'A stable tracking control method for an "
                   "autonomous mobile robot'", (
                       Param("speed_m_s", "m/s", 0.15, 0.01, 1.0, "reference speed v_r"),
                       Param("k_x_1_s", "1/s", 3.0, 0.0, 50.0, "gain on the along-track error"),
                       Param("k_y_1_m2", "1/m^2", 900.0, 0.0, 10000.0, "gain on the cross-track error"),
                       Param("k_theta_1_m", "1/m", 60.0, 0.0, 1000.0, "gain on the heading error"),
                       Param("max_lead_m", "m", 0.03, 0.005, 1.0, "the reference waits while it is this far ahead "
                             "of the robot's projection"),
                       Param("rotate_to_heading_rad", "rad", 0.5, 0.1, math.pi,
                             "turn on the spot while the reference's heading is further off"),
                       *REPLAN_PARAMS)),
)}


class Controller(Plugin):
    """The interface of a plug-in controller (a :class:`~contract.plugins.Plugin`: ``configure`` once before
    first use, ``cleanup`` when dropped): ``parameters`` (numbers), ``description``, ``source`` and
    :meth:`command`.  Plug-ins need not subclass it: an object with these attributes will do."""

    source: str = ""
    parameters: Sequence[Param] = ()

    def command(self, pose: np.ndarray, path: np.ndarray, progress: tuple[int, float], params: dict[str, float],
                dt: float) -> tuple[float, float]:
        """Body velocities ``(v, w)`` (m/s, rad/s) for the believed ``pose`` on ``path`` (see the module)."""
        raise NotImplementedError


#: the older name of the interface
PluginController = Controller


def _declared(obj: Any) -> tuple[Any, ...]:
    """A controller object's declared parameters: ``parameters``, or the older ``params``."""
    declared = getattr(obj, "parameters", None) or getattr(obj, "params", None) or ()
    return tuple(declared)


def _adapt(name: str, obj: Any, source: str) -> ControllerSpec:
    """A created, configured plug-in object as the :class:`ControllerSpec` ``name``; TypeError if it lacks the
    interface."""
    params = _declared(obj)
    if not callable(getattr(obj, "command", None)) or not all(isinstance(p, Param) for p in params):
        raise TypeError("a controller has `command(pose, path, progress, params, dt)` and `parameters` (Param)")
    if len(params) > _SLOTS:
        raise TypeError(f"a controller has at most {_SLOTS} parameters")
    words = [p.name for p in params if p.type not in ("number", "integer")]
    if words:
        raise TypeError(f"a controller's parameters are numbers (type number or integer); not {', '.join(words)}")
    desc = str(getattr(obj, "description", "") or f"plug-in {source}")
    return ControllerSpec(name, _PLUGIN_ID, desc, str(getattr(obj, "source", "") or source), params, obj)


def _refuse(message: str) -> ControllerError:
    return ControllerError("controller", message)


#: the plug-in controllers of this process
PLUGINS: PluginRegistry[ControllerSpec] = PluginRegistry("controller", ENTRY_POINT_GROUP, adapt=_adapt,
                                                         refuse=_refuse, reserved=BUILTINS)


def register_controller(name: str, obj: Any) -> ControllerSpec:
    """Register a plug-in controller object under ``name`` for this process (tests, notebooks)."""
    return PLUGINS.register(name, obj)


def unregister_controller(name: str) -> None:
    """Drop the plug-in controller ``name`` of this process (its ``cleanup`` runs); nothing if it is not loaded."""
    PLUGINS.unregister(name)


def controller_spec(name: str) -> ControllerSpec:
    """The controller called ``name``; :class:`ControllerError` listing the choices if none, or saying why a
    plug-in failed to load (its :class:`~contract.plugins.LoadError` as ``load_error``)."""
    if name in BUILTINS:
        return BUILTINS[name]
    spec = PLUGINS.get(name)
    if spec is None:
        raise ControllerError("controller", f"unknown controller {name!r} (available: "
                                            f"{', '.join(available_controllers())})")
    return spec


def controller_report() -> list[PluginStatus]:
    """Every installed plug-in controller, loaded now (or tried): what ``twb plugins list`` shows."""
    return PLUGINS.report()


def available_controllers() -> list[str]:
    """Every selectable controller name: the built-ins, then plug-ins (by name)."""
    return [*BUILTINS, *PLUGINS.names()]


@dataclass(frozen=True)
class Selection:
    """A controller chosen for a path: its spec, the full parameters (defaults filled in) and the compiled
    core's parameter row ``(PARAM_SLOTS,)``."""

    spec: ControllerSpec
    params: dict[str, float]

    @property
    def row(self) -> np.ndarray:
        """The compiled parameters in spec order, zero-padded to the table's width."""
        out = np.zeros(_SLOTS)
        values = [self.params[p.name] for p in self.spec.params if p.compiled]
        out[:len(values)] = values
        return out

    @property
    def replans(self) -> bool:
        """Whether the robot replans around what blocks its path (``replan`` = 1)."""
        return self.params.get("replan", 0.0) == 1.0


def select(name: Optional[str] = None, params: Optional[Mapping[str, Any]] = None) -> Selection:
    """Validate a controller choice: ``name`` (default ``schema``) and ``params`` (names of its parameters,
    numbers in their ranges); :class:`ControllerError` naming the field otherwise."""
    spec = controller_spec(name or DEFAULT_CONTROLLER)
    try:
        checked = check_values(spec.params, params, owner=f"controller {spec.name!r}", label="controller_params.")
    except ParamError as exc:
        where = f"controller_params.{exc.param}"
        raise ControllerError(where, f"{where}: {exc}" if exc.unknown else str(exc)) from None
    out = {k: float(v) for k, v in checked.items()}
    if spec.name == "regulated_pure_pursuit" and out["min_lookahead_m"] > out["max_lookahead_m"]:
        raise ControllerError("controller_params.min_lookahead_m", "controller_params.min_lookahead_m must not "
                                                                   "exceed max_lookahead_m")
    return Selection(spec, out)
