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


def smooth_descent(space: ConfigSpace, path: np.ndarray, passes: int) -> tuple[np.ndarray, int]:
    """``path`` ``(N, 2)`` (m) after ``passes`` binomial [1, 2, 1] / 4 passes over its inner points, each moved
    point kept only while both its segments stay free (exact segment test); the ends stay.

    The descent of an FM² field zigzags across the valley of the travel time wherever the speed map has a
    ridge (the medial axis of every corridor narrower than twice ``saturation``): there the valley has no
    curvature to settle in and a step of one cell crosses it back and forth, half a cell to each side, ahead
    of the 5 mm simplification.  One pass cancels a zigzag of period two exactly and leaves the path's long
    bends nearly unchanged.  Returns the path and how many moves were refused (collision).
    """
    p = np.array(path, dtype=float)
    refused = 0
    for _ in range(passes):
        if len(p) < 3:
            break
        new = p.copy()
        new[1:-1] = 0.25 * p[:-2] + 0.5 * p[1:-1] + 0.25 * p[2:]
        while True:  # undo the moves next to a blocked segment until every segment is free
            bad = np.flatnonzero(~space.segments_free(new[:-1], new[1:]))
            if len(bad) == 0:
                break
            idx = np.unique(np.r_[bad, bad + 1])
            idx = idx[(idx > 0) & (idx < len(p) - 1)]
            idx = idx[np.any(new[idx] != p[idx], axis=1)]
            refused += len(idx)
            new[idx] = p[idx]
        p = new
    return p, refused


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
        Param("smooth", "passes", 2, 0, 20, "binomial smoothing passes over the descent (0: the raw descent)",
              type="integer"),
    )

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        speed = speed_map(space, params["saturation"], params["min_speed"])
        path, info = plan(space, start, goal, speed, step=params["step"])
        if params["smooth"]:
            path, info["smooth_refused"] = smooth_descent(space, path, params["smooth"])
        return path, info
