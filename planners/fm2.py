"""Fast Marching Square (FM², Garrido et al.): fast marching through a clearance-based speed map.

The speed at a free cell is its clearance beyond the robot radius divided by
``saturation`` (metres), clipped to ``[min_speed, 1]``: the front is slow near
obstacles and at full speed beyond the saturation distance, so the descent
keeps away from obstacles where there is room and stays smooth.  As for FMM,
the front is marched only as far as the query needs
(:func:`planners.fast_marching.plan`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Param, Planner
from .fast_marching import plan
from .grid import ConfigSpace

__all__ = ["FM2Planner", "speed_map"]


def speed_map(space: ConfigSpace, saturation: float, min_speed: float = 0.01) -> np.ndarray:
    """FM² speed (normalised to [0, 1]) of every cell from the Euclidean distance transform."""
    margin = space.grid.clearance - space.radius
    return np.clip(margin / saturation, min_speed, 1.0)


class FM2Planner(Planner):
    """Fast Marching Square: smooth paths that keep clearance up to ``saturation`` metres."""

    name = "fm2"
    description = "Fast Marching Square: clearance-weighted fast marching (smooth, safe paths)"
    parameters = (
        Param("saturation", "m", 0.2, 0.0, None, "clearance beyond the robot radius at which the speed reaches 1",
              low_exclusive=True),
        Param("min_speed", "", 0.01, 0.0, 1.0, "the lowest normalised speed (next to obstacles)", low_exclusive=True),
        Param("step", "cells", 1.0, 0.05, 1.0, "length of a descent step along the travel time's gradient"),
    )

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        speed = speed_map(space, params["saturation"], params["min_speed"])
        return plan(space, start, goal, speed, step=params["step"])
