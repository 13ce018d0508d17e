"""The planner interface every built-in and plug-in planner implements.

A planner gets a :class:`~planners.grid.ConfigSpace` (obstacles already
dilated by the robot radius), a start and a goal ``(x, y)`` in metres that are
known to be free and connected, validated parameters and a seed, and returns
the raw path: an ``(N, 2)`` array of points in metres from exactly ``start`` to
exactly ``goal`` whose segments lie in free space.  Post-processing
(trimming, headings) and timing are done once, for all planners, by
:func:`planners.plan_path`.

Write a plug-in by subclassing :class:`Planner`::

    class StraightLine(Planner):
        name = "straight"
        description = "Straight segment; fails if blocked"
        parameters = (Param("margin", "m", 0.0, 0.0, 0.5, "unused: an example"),)

        def solve(self, space, start, goal, params, seed):
            path = np.array([start, goal])
            if not space.path_free(path):
                raise NoPathFound("the straight segment is blocked")
            return path

and registering it under the entry-point group ``teleworkbench.planners``
(see docs/planners.md).  A planner is a :class:`contract.plugins.Plugin`: the
loader calls its ``configure()`` once before first use and ``cleanup()`` when
it is dropped; its parameters are :class:`contract.parameters.Param` s, as a
controller's.
"""

from __future__ import annotations

from typing import Any, Mapping, Optional, Sequence

import numpy as np

from contract.parameters import Param, check_values, defaults_of, params_from_defaults
from contract.plugins import Plugin

from .grid import ConfigSpace

__all__ = ["Param", "Planner", "SolveResult"]

SolveResult = np.ndarray | tuple[np.ndarray, dict[str, Any]]


class _Defaults:
    """``defaults``: the declared parameters as ``{name: default}`` (None: any parameters).

    The older way to declare parameters, a ``defaults`` dict (each value's type the parameter's), still
    works: assigning one, on a subclass or an instance, declares :attr:`Planner.parameters` from it.
    """

    def __get__(self, obj: Optional["Planner"], owner: type) -> Optional[dict[str, Any]]:
        return defaults_of((owner if obj is None else obj).parameters)

    def __set__(self, obj: "Planner", value: Optional[Mapping[str, Any]]) -> None:
        obj.parameters = params_from_defaults(value)


class Planner(Plugin):
    """Base class of planners: set ``name``, ``description``, ``parameters`` and implement :meth:`solve`.

    ``parameters`` declares each accepted parameter (:class:`~contract.parameters.Param`: type, default,
    range, unit, description); ``None`` accepts any JSON parameters unchecked.  Rules between parameters go
    in :meth:`check_params`.
    """

    parameters: Optional[Sequence[Param]] = ()
    defaults = _Defaults()
    #: whether the path depends on the seed (a randomised planner such as PRM).  The testbed plans a
    #: stochastic planner once per repetition, with that repetition's planner seed, so that its randomness is
    #: a result (every run drives its own draw); a deterministic planner's one path is reused by every run and
    #: only timed again per repetition (docs/planners.md, "Randomised planners").
    stochastic: bool = False

    def forget(self) -> None:
        """Drop whatever the planner keeps from earlier calls (a cache), so that the next call plans from scratch.

        A run's planning time is the time of a first call (docs/study.md, "Planning time"): the testbed calls
        this before every timed call.  Default: nothing is kept.
        """

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "defaults" in cls.__dict__ and not isinstance(cls.__dict__["defaults"], _Defaults):
            if "parameters" not in cls.__dict__:  # the older form: a defaults dict declares the parameters
                cls.parameters = params_from_defaults(cls.__dict__["defaults"])
            delattr(cls, "defaults")  # the base's view takes over

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> SolveResult:
        """Return the ``(N, 2)`` raw path (m) from ``start`` to ``goal``, optionally with an info dict."""
        raise NotImplementedError

    def validate_params(self, params: Mapping[str, Any] | None) -> dict[str, Any]:
        """``params`` over the declared defaults, each checked (:func:`~contract.parameters.check_values`),
        then :meth:`check_params`; ``ValueError`` (:class:`~contract.parameters.ParamError`) naming the
        parameter otherwise."""
        if self.parameters is None:
            return dict(params or {})
        out = check_values(self.parameters, params, owner=f"planner {self.name!r}", label=f"parameter {self.name}.")
        self.check_params(out)
        return out

    def check_params(self, params: dict[str, Any]) -> None:
        """Rules between checked parameters; raise ``ValueError`` naming the parameter and the rule."""
