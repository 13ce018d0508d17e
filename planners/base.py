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
        defaults = {}

        def solve(self, space, start, goal, params, seed):
            path = np.array([start, goal])
            if not space.path_free(path):
                raise NoPathFound("the straight segment is blocked")
            return path

and registering it under the entry-point group ``teleworkbench.planners``
(see docs/planners.md).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from .grid import ConfigSpace

__all__ = ["Planner", "SolveResult"]

SolveResult = np.ndarray | tuple[np.ndarray, dict[str, Any]]


class Planner:
    """Base class of planners: set ``name``, ``description``, ``defaults`` and implement :meth:`solve`.

    ``defaults`` maps each accepted parameter to its default value; the type of
    the default (bool, int, float, str) is the type a user value must have.
    Set ``defaults = None`` to accept any JSON parameters unchecked.
    """

    name: str = ""
    description: str = ""
    defaults: Mapping[str, Any] | None = {}
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

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> SolveResult:
        """Return the ``(N, 2)`` raw path (m) from ``start`` to ``goal``, optionally with an info dict."""
        raise NotImplementedError

    def validate_params(self, params: Mapping[str, Any] | None) -> dict[str, Any]:
        """Merge ``params`` over ``defaults``; ``ValueError`` naming an unknown or mistyped parameter."""
        params = dict(params or {})
        if self.defaults is None:
            return params
        out = dict(self.defaults)
        for key, value in params.items():
            if key not in self.defaults:
                allowed = ", ".join(sorted(self.defaults)) or "none"
                raise ValueError(f"planner {self.name!r} has no parameter {key!r} (parameters: {allowed})")
            default = self.defaults[key]
            out[key] = _coerce(value, default, f"{self.name}.{key}")
        self.check_params(out)
        return out

    def check_params(self, params: dict[str, Any]) -> None:
        """Range checks of merged parameters; raise ``ValueError`` naming the parameter and the rule."""


def _coerce(value: Any, default: Any, where: str) -> Any:
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"parameter {where} must be true or false, got {value!r}")
        return value
    if isinstance(default, (int, float)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"parameter {where} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ValueError(f"parameter {where} must be finite, got {value!r}")
        if isinstance(default, int):
            if float(value) != int(value):
                raise ValueError(f"parameter {where} must be an integer, got {value!r}")
            return int(value)
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ValueError(f"parameter {where} must be a string, got {value!r}")
        return value
    return value
