"""FMM planner: shortest collision-free path by fast marching at unit speed.

The arrival time of a front started at the goal is the geodesic distance in
the configuration space; its descent from the start is the shortest path,
which hugs obstacle corners at exactly the robot radius.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Planner
from .fast_marching import descend, travel_time
from .grid import ConfigSpace

__all__ = ["FMMPlanner"]


class FMMPlanner(Planner):
    """Fast Marching Method (Sethian) with unit speed over free space."""

    name = "fmm"
    description = "Fast Marching Method: geodesic shortest path (scikit-fmm), sub-cell descent"
    defaults = {"step": 1.0}

    def check_params(self, params: dict[str, Any]) -> None:
        if not 0.05 <= params["step"] <= 1.0:
            raise ValueError("parameter fmm.step must be in [0.05, 1] cells")

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        t = travel_time(space, goal)
        return descend(space, t, start, goal, step=params["step"])
