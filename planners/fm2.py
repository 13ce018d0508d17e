"""Fast Marching Square (FM², Garrido et al.): fast marching through a clearance-based speed map.

The speed at a free cell is its clearance beyond the robot radius divided by
``saturation`` (metres), clipped to ``[min_speed, 1]``: the front is slow near
obstacles and at full speed beyond the saturation distance, so the descent
keeps away from obstacles where there is room and stays smooth.  As for FMM,
the front is marched only as far as the query needs
(:func:`planners.fast_marching.plan`).  The descent is smoothed
(:func:`smooth_descent`) and then straightened inside the band of clearance it
keeps (:func:`band_shortcut`); then the straightened path's corners are cut (``round``,
three passes by default; :func:`round_corners`), so the path is the smooth curve FM² is
known for rather than a polyline with corners.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Param, Planner
from .fast_marching import plan
from .geometry import block_arrays, distance_to_obstacles
from .grid import ConfigSpace
from .postprocess import simplify

__all__ = ["FM2Planner", "band_shortcut", "round_corners", "smooth_descent", "speed_map"]

#: the furthest (in corners of the simplified descent) a chord of :func:`band_shortcut` reaches ahead
SHORTCUT_WINDOW = 64
#: the corner tolerance of :func:`band_shortcut` in FM2Planner, in cells (half a cell: 5 mm at 1 cm, the
#: post-processing's default)
SHORTCUT_TOLERANCE = 0.5


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


def band_shortcut(space: ConfigSpace, path: np.ndarray, tolerance: float) -> tuple[np.ndarray, int]:
    """``path`` ``(N, 2)`` (m) straightened inside the band of clearance it keeps.

    In clutter the FM² descent follows the medial axis between the blocks: the speed map, a monotone function
    of the clearance, has a ridge with a kink there, so leaving the axis costs travel time to first order and
    the geodesic weaves with every bend of the axis (5.8 rad of turning against fmm's 1.8 in the problem
    set's clutter).  Here the path is first reduced to its corners (collision-aware
    Ramer-Douglas-Peucker, ``tolerance`` m), then, from the start, each corner is joined to the furthest later
    corner (at most :data:`SHORTCUT_WINDOW` ahead) whose chord keeps, by the exact distance to blocks and
    walls, at least the smaller of the clearances the path has at the chord's two ends, and is free in
    ``space`` (exact segment test).  So every point of the result is at least as far from obstacles as the
    descent is at one end of the run it replaces: the path's smallest clearance is never lowered (below the
    corners'), and where the descent keeps the saturation distance (open space) the chord does too.  The ends
    stay.  Returns the kept corners ``(K, 2)`` (m) and how many corners were cut.
    """
    from ._band import band_chain  # numba loads with the first FM² plan (planners.fast_marching does too)

    corners = np.asarray(path, dtype=float)[:, :2]
    corners = np.ascontiguousarray(corners[simplify(corners, tolerance, space)])
    n = len(corners)
    if n < 3:
        return corners, 0
    centres, half, angles = block_arrays(space.env)
    blocks = np.ascontiguousarray(np.column_stack([centres, np.cos(angles), np.sin(angles), half]), dtype=float)
    ny, nx = space.free.shape
    keep = band_chain(corners, distance_to_obstacles(space.env, corners), blocks, float(space.env.width),
                      float(space.env.height), np.ascontiguousarray(space.free.ravel(), dtype=np.uint8), nx, ny,
                      1.0 / space.resolution, SHORTCUT_WINDOW)
    return corners[keep], n - len(keep)


def round_corners(space: ConfigSpace, path: np.ndarray, passes: int) -> tuple[np.ndarray, int]:
    """``path`` ``(N, 2)`` (m) with its corners cut, ``passes`` times (Chaikin: every segment replaced by the points
    at its quarter and three quarters, the ends kept), a pass kept only if every new segment is free (exact
    segment test): a polyline's corners become curves of a few centimetres' radius that keep near the chords.
    Returns the path and how many passes were refused (collision)."""
    p = np.asarray(path, dtype=float)[:, :2]
    for k in range(passes):
        if len(p) < 3:
            return p, 0
        a, b = p[:-1], p[1:]
        cut = np.empty((2 * len(a), 2))
        cut[0::2] = 0.75 * a + 0.25 * b
        cut[1::2] = 0.25 * a + 0.75 * b
        new = np.vstack([p[:1], cut[1:-1], p[-1:]])
        if not space.segments_free(new[:-1], new[1:]).all():
            return p, passes - k
        p = new
    return p, 0


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
        Param("shortcut", "", True, None, None, "replace runs of the smoothed descent by chords that keep the "
              "clearance it has at their ends (false: the smoothed descent)", type="boolean"),
        Param("round", "passes", 3, 0, 6, "corner-cutting passes over the result (Chaikin; each kept only if the "
              "path stays free): the straightened path's corners become short curves (0: its polyline)",
              type="integer"),
    )

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        speed = speed_map(space, params["saturation"], params["min_speed"])
        path, info = plan(space, start, goal, speed, step=params["step"])
        if params["smooth"]:
            path, info["smooth_refused"] = smooth_descent(space, path, params["smooth"])
        if params["shortcut"]:
            path, info["shortcut_cut"] = band_shortcut(space, path, SHORTCUT_TOLERANCE * space.resolution)
        if params["round"]:
            path, info["round_refused"] = round_corners(space, path, params["round"])
        return path, info
