"""The exact segment test of :meth:`planners.grid.ConfigSpace.segments_free` for one segment at a time (numba).

Planners that test segments one by one inside a search (Theta*'s line of sight, OMPL's motion validator) call
:func:`segment_free`: the same floating-point operations, in the same order, as the vectorised test, so both
agree on every segment (``tests/test_anyangle.py`` checks random ones), at about a microsecond a call instead
of tens.  Imported lazily (numba loads with it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_jit = njit(cache=True, nogil=True)


@_jit
def point_free(free, nx, ny, inv_h, width, height, x, y):
    """``ConfigSpace.is_free`` of one point (m): inside the field and in a free cell (``free``: flat uint8)."""
    fx = math.floor(x * inv_h)
    fy = math.floor(y * inv_h)
    if x == width:
        fx = nx - 1
    if y == height:
        fy = ny - 1
    if not (fx >= 0 and fx < nx and fy >= 0 and fy < ny):  # NaN compares False
        return False
    return free[int(fy) * nx + int(fx)] != 0


@_jit
def segment_free(free, nx, ny, inv_h, width, height, ax, ay, bx, by):
    """``ConfigSpace.segments_free`` of the one segment (ax, ay) -> (bx, by) (m): both ends free and every grid
    line it crosses has free cells on both sides (a cell touched only at a corner is not crossed)."""
    if not (point_free(free, nx, ny, inv_h, width, height, ax, ay)
            and point_free(free, nx, ny, inv_h, width, height, bx, by)):
        return False
    a0 = ax * inv_h
    a1 = ay * inv_h
    d0 = bx * inv_h - a0
    d1 = by * inv_h - a1
    p = d0 * d1
    tilt = 1e-9 * (1.0 if p > 0 else (-1.0 if p < 0 else 0.0))
    for axis in range(2):
        if axis == 0:
            a_ax, d_ax, a_ot, d_ot, n_ax, n_ot = a0, d0, a1, d1, nx, ny
        else:
            a_ax, d_ax, a_ot, d_ot, n_ax, n_ot = a1, d1, a0, d0, ny, nx
        e = a_ax + d_ax
        lo = math.floor(min(a_ax, e)) + 1.0
        hi = math.ceil(max(a_ax, e)) - 1.0
        k = lo
        while k <= hi:
            t = (k - a_ax) / d_ax
            along = a_ot + d_ot * t
            for s in range(2):
                side = k - 1.0 if s == 0 else k
                shift = -tilt if s == 0 else tilt
                c_ax = int(min(max(side, 0.0), n_ax - 1.0))
                c_ot = int(min(max(math.floor(along + shift), 0.0), n_ot - 1.0))
                idx = c_ot * nx + c_ax if axis == 0 else c_ax * nx + c_ot
                if free[idx] == 0:
                    return False
            k += 1.0
    return True


@_jit
def segments_free_batch(free, nx, ny, inv_h, width, height, a, b):
    """:func:`segment_free` of every segment ``a[i] -> b[i]`` (``(S, 2)`` arrays, m): ``(S,)`` bool."""
    out = np.empty(len(a), dtype=np.bool_)
    for i in range(len(a)):
        out[i] = segment_free(free, nx, ny, inv_h, width, height, a[i, 0], a[i, 1], b[i, 0], b[i, 1])
    return out


class SegmentTest:
    """:func:`segment_free` and :func:`point_free` bound to one configuration space."""

    def __init__(self, space) -> None:  # type: ignore[no-untyped-def]
        ny, nx = space.free.shape
        self.args = (np.ascontiguousarray(space.free.ravel(), dtype=np.uint8), nx, ny, 1.0 / space.resolution,
                     float(space.env.width), float(space.env.height))

    def segment(self, ax: float, ay: float, bx: float, by: float) -> bool:
        """Whether the segment (ax, ay) -> (bx, by) (m) is free."""
        return bool(segment_free(*self.args, ax, ay, bx, by))

    def point(self, x: float, y: float) -> bool:
        """Whether the point (x, y) (m) is free."""
        return bool(point_free(*self.args, x, y))

    def segments(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """:meth:`~planners.grid.ConfigSpace.segments_free` of ``a[i] -> b[i]`` (m), compiled: ``(S,)`` bool."""
        return segments_free_batch(*self.args, np.ascontiguousarray(a[:, :2], dtype=float),
                                   np.ascontiguousarray(b[:, :2], dtype=float))
