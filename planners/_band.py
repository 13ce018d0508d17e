"""The compiled chord search of :func:`planners.fm2.band_shortcut` (numba, imported lazily).

A chord qualifies when its exact clearance (distance to the field's walls and to every block, the operations
of :func:`planners.geometry.segment_clearance`: each block in its own frame, the separating-axis test, then
the ends' distances to the box and the box corners' distances to the segment) is at least the smaller of the
clearances the path has at its two ends, and it is free in the configuration space
(:func:`planners._segment.segment_free`).  A block is rejected as soon as it comes closer than that, so a
chord through clutter costs a few blocks' tests, not all of them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._segment import segment_free

_jit = njit(cache=True, nogil=True)


@_jit
def _box_distance(lx, ly, hx, hy):
    """Signed distance (m) from the local point (lx, ly) to the box [-hx, hx] x [-hy, hy]; negative inside."""
    ex = abs(lx) - hx
    ey = abs(ly) - hy
    return math.hypot(max(ex, 0.0), max(ey, 0.0)) + min(max(ex, ey), 0.0)


@_jit
def _segment_box_distance(ax, ay, bx, by, hx, hy):
    """Exact distance (m) from the segment a -> b to the box [-hx, hx] x [-hy, hy], all in the box frame; 0 when
    they meet."""
    dx = bx - ax
    dy = by - ay
    if (min(ax, bx) <= hx and max(ax, bx) >= -hx and min(ay, by) <= hy and max(ay, by) >= -hy
            and abs(dx * ay - dy * ax) <= hx * abs(dy) + hy * abs(dx)):
        return 0.0
    best = min(_box_distance(ax, ay, hx, hy), _box_distance(bx, by, hx, hy))
    len2 = dx * dx + dy * dy
    inv = 1.0 / len2 if len2 > 0 else 0.0
    for k in range(4):
        sx = -1.0 if k == 0 or k == 3 else 1.0
        sy = -1.0 if k < 2 else 1.0
        cx = sx * hx - ax
        cy = sy * hy - ay
        t = min(max((cx * dx + cy * dy) * inv, 0.0), 1.0)
        best = min(best, math.hypot(cx - t * dx, cy - t * dy))
    return best


@_jit
def _keeps(blocks, width, height, ax, ay, bx, by, need):
    """Whether the segment a -> b (m) keeps at least ``need`` metres from the walls and every block.

    ``blocks`` rows: centre x, centre y, cos, sin of the angle, half width, half height.
    """
    if min(min(ax, width - ax), min(ay, height - ay), min(bx, width - bx), min(by, height - by)) < need:
        return False
    for b in range(blocks.shape[0]):
        cx = blocks[b, 0]
        cy = blocks[b, 1]
        c = blocks[b, 2]
        s = blocks[b, 3]
        adx = ax - cx
        ady = ay - cy
        bdx = bx - cx
        bdy = by - cy
        if _segment_box_distance(c * adx + s * ady, c * ady - s * adx, c * bdx + s * bdy, c * bdy - s * bdx,
                                 blocks[b, 4], blocks[b, 5]) < need:
            return False
    return True


@_jit
def band_chain(pts, at, blocks, width, height, free, nx, ny, inv_h, window):
    """Indices of the corners ``pts`` ``(n, 2)`` (m) kept: from the first, each kept corner is joined to the
    furthest later one (at most ``window`` ahead) whose chord keeps ``min(at[i], at[j])`` (m; ``at``: the
    clearance at each corner) and is free (``free``: the flat uint8 free cells, ``nx`` x ``ny``, ``inv_h``
    cells per metre), or to the next corner when none does."""
    n = pts.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    m = 1
    i = 0
    while i < n - 1:
        nxt = i + 1
        for j in range(min(n - 1, i + window), i + 1, -1):
            if (_keeps(blocks, width, height, pts[i, 0], pts[i, 1], pts[j, 0], pts[j, 1], min(at[i], at[j]))
                    and segment_free(free, nx, ny, inv_h, width, height, pts[i, 0], pts[i, 1], pts[j, 0],
                                     pts[j, 1])):
                nxt = j
                break
        keep[m] = nxt
        m += 1
        i = nxt
    return keep[:m]
