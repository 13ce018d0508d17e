"""Path post-processing, as the paper does before sending a path to a robot.

1. :func:`simplify` — keep the corners: collision-aware Ramer–Douglas–Peucker
   keeps the points where the raw path turns (deviation > ``tolerance``)
   and any point needed to keep every chord in free space.
2. :func:`trim` — uniform arc-length sampling between kept corners with a
   spacing of at most ``max_spacing`` metres (corners stay exactly).
3. :func:`headings` — a heading for every point: the direction of travel,
   and the goal's heading at the last point.

All take and return arrays in metres/radians.
"""

from __future__ import annotations

import math

import numpy as np

from .grid import ConfigSpace

__all__ = ["headings", "postprocess", "simplify", "trim"]


def _distance_to_chord(xs: np.ndarray, ys: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
    """Squared distance (m²) from points (xs, ys) to the segment a -> b (plain ufuncs: called often)."""
    px, py = xs - a[0], ys - a[1]
    dx, dy = b[0] - a[0], b[1] - a[1]
    denom = dx * dx + dy * dy
    if denom == 0.0:
        return px * px + py * py
    t = np.minimum(np.maximum((px * dx + py * dy) * (1.0 / denom), 0.0), 1.0)
    ex, ey = px - t * dx, py - t * dy
    return ex * ex + ey * ey


def simplify(path: np.ndarray, tolerance: float, space: ConfigSpace | None = None) -> np.ndarray:
    """Indices of the points of ``path`` ``(N, 2)`` kept by (collision-aware) Ramer–Douglas–Peucker.

    A chord replaces the points between its ends when all of them are within
    ``tolerance`` metres of it and, if ``space`` is given, the chord is free
    (its segments must be free in ``space`` to begin with).  The geometric
    pass loops once per kept point with the work vectorised over points; the
    chords are then collision-checked all at once and the few that collide
    are split at their farthest point until every chord is free.
    """
    if tolerance < 0:
        raise ValueError("`tolerance` must be >= 0 (metres)")
    n = len(path)
    if n <= 2:
        return np.arange(n)
    xs, ys = np.ascontiguousarray(path[:, 0]), np.ascontiguousarray(path[:, 1])
    pt = list(zip(xs.tolist(), ys.tolist()))
    tol2 = tolerance * tolerance
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        d = _distance_to_chord(xs[i + 1 : j], ys[i + 1 : j], pt[i], pt[j])
        split = int(d.argmax())
        if d[split] > tol2:
            m = i + 1 + split
            keep[m] = True
            stack += [(i, m), (m, j)]
    if space is None:
        return np.flatnonzero(keep)
    while True:
        idx = np.flatnonzero(keep)
        bad = ~space.segments_free(path[idx[:-1]], path[idx[1:]])
        if not bad.any():
            return idx
        for i, j in zip(idx[:-1][bad], idx[1:][bad]):
            if j - i < 2:
                raise ValueError("`path` itself leaves free space")
            d = _distance_to_chord(xs[i + 1 : j], ys[i + 1 : j], pt[i], pt[j])
            keep[i + 1 + int(d.argmax())] = True


def trim(path: np.ndarray, max_spacing: float) -> np.ndarray:
    """Insert evenly spaced points on every segment so no spacing exceeds ``max_spacing`` (m).

    All input vertices are kept; zero-length segments are dropped.
    """
    if not (math.isfinite(max_spacing) and max_spacing > 0):
        raise ValueError("`max_spacing` must be a finite number > 0 (metres)")
    p = np.asarray(path, dtype=float)[:, :2]
    if len(p) < 2:
        return p.copy()
    seg = np.diff(p, axis=0)
    length = np.hypot(*seg.T)
    keep = np.r_[True, length > 1e-12]
    keep[-1] = True
    p = p[keep] if keep.sum() >= 2 else p[[0, -1]]
    seg = np.diff(p, axis=0)
    length = np.hypot(*seg.T)
    pieces = np.maximum(np.ceil(length / max_spacing - 1e-9).astype(np.int64), 1)
    owner = np.repeat(np.arange(len(seg)), pieces)
    first = np.cumsum(pieces) - pieces
    frac = (np.arange(pieces.sum()) - np.repeat(first, pieces)) / np.repeat(pieces, pieces)
    out = p[owner] + seg[owner] * frac[:, None]
    return np.vstack([out, p[-1:]])


def headings(path: np.ndarray, final_heading: float | None = None) -> np.ndarray:
    """``(N, 3)`` path with a heading (rad) for every point of ``path`` ``(N, 2)``.

    Each point faces the next one; the last point gets ``final_heading`` if
    given, else the direction of the last segment.  A single point gets
    ``final_heading`` or 0.
    """
    p = np.asarray(path, dtype=float)[:, :2]
    theta = np.zeros(len(p))
    if len(p) >= 2:
        d = np.diff(p, axis=0)
        theta[:-1] = np.arctan2(d[:, 1], d[:, 0])
        theta[-1] = theta[-2]
    if final_heading is not None:
        theta[-1] = final_heading
    return np.column_stack([p, theta])


def postprocess(
    raw: np.ndarray,
    *,
    space: ConfigSpace | None,
    tolerance: float = 0.005,
    max_spacing: float = 0.1,
    final_heading: float | None = None,
) -> np.ndarray:
    """Simplify, trim and add headings: the ``(N, 3)`` path a robot is sent."""
    raw = np.asarray(raw, dtype=float)[:, :2]
    corners = raw[simplify(raw, tolerance, space)]
    return headings(trim(corners, max_spacing), final_heading)
