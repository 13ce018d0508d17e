"""FMM planner: shortest collision-free path by fast marching at unit speed.

The arrival time of a front started at the goal is the geodesic distance in
the configuration space; its descent from the start is the shortest path,
which hugs obstacle corners at exactly the robot radius.  The front is
marched only until the start and the cells the descent reads are accepted
(:func:`planners.fast_marching.plan`): the same arrival times and path as
the full field of ``skfmm.travel_time``, at the cost of the cells accepted.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Param, Planner
from .fast_marching import plan
from .grid import ConfigSpace

__all__ = ["FMMPlanner"]


class FMMPlanner(Planner):
    """Fast Marching Method (Sethian) with unit speed over free space."""

    name = "fmm"
    description = "Fast Marching Method: geodesic shortest path (scikit-fmm's scheme), sub-cell descent"
    parameters = (Param("step", "cells", 1.0, 0.05, 1.0, "length of a descent step along the travel time's "
                        "gradient"),)

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        return plan(space, start, goal, step=params["step"])
