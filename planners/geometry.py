"""Exact, vectorised geometry of an environment: signed distances to blocks and walls.

All functions take ``(N, 2)`` arrays of points in metres and return arrays; no
loops over points.  These are the exact references that the occupancy grid
approximates and that clearance metrics use.
"""

from __future__ import annotations

import numpy as np

from .environment import Environment

__all__ = [
    "block_arrays",
    "block_corners",
    "distance_to_obstacles",
    "inside_field",
    "polyline_clearance",
    "polyline_min_clearance",
    "sample_segments",
    "segment_clearance",
    "segment_distance_to_obstacles",
    "signed_distance_to_blocks",
]


def block_arrays(env: Environment) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blocks as arrays: centres ``(B, 2)`` m, half sizes ``(B, 2)`` m, angles ``(B,)`` rad."""
    if not env.blocks:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    a = np.array([(b.x, b.y, b.w / 2, b.h / 2, b.angle) for b in env.blocks], dtype=float)
    return a[:, :2], a[:, 2:4], a[:, 4]


def block_corners(env: Environment) -> np.ndarray:
    """Corners of every block, ``(B, 4, 2)`` m, counter-clockwise from (-w/2, -h/2)."""
    centres, half, angles = block_arrays(env)
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    local = signs[None, :, :] * half[:, None, :]
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x = c * local[..., 0] - s * local[..., 1]
    y = s * local[..., 0] + c * local[..., 1]
    return np.stack([x, y], axis=-1) + centres[:, None, :]


def _as_points(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] < 2:
        raise ValueError(f"`points` must have shape (N, 2) or (N, 3), got {p.shape}")
    return p[:, :2]


def signed_distance_to_blocks(env: Environment, points: np.ndarray) -> np.ndarray:
    """Signed distance (m) from each point to the nearest block; negative inside a block.

    Returns ``+inf`` for every point when the environment has no blocks.
    """
    p = _as_points(points)
    centres, half, angles = block_arrays(env)
    if len(centres) == 0:
        return np.full(len(p), np.inf)
    lx, ly = _block_local(p, centres, angles)
    return _box_signed_distance(lx, ly, half[:, 0], half[:, 1]).min(axis=1)


def _block_local(p: np.ndarray, centres: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (m) of points ``(N, 2)`` in every block's own frame: two ``(N, B)`` arrays."""
    return _to_frame(p[:, None, 0], p[:, None, 1], centres[:, 0], centres[:, 1], np.cos(angles), np.sin(angles))


def _to_frame(
    x: np.ndarray, y: np.ndarray, cx: np.ndarray, cy: np.ndarray, c: np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of ``(x, y)`` in frames centred at ``(cx, cy)`` turned by the angle of cosine ``c``, sine ``s``."""
    dx, dy = x - cx, y - cy
    return c * dx + s * dy, c * dy - s * dx


def _box_signed_distance(lx: np.ndarray, ly: np.ndarray, hx: np.ndarray, hy: np.ndarray) -> np.ndarray:
    """Signed distance (m) from local coordinates to the box ``[-hx, hx] x [-hy, hy]``; negative inside."""
    ex, ey = np.abs(lx) - hx, np.abs(ly) - hy
    return np.hypot(np.maximum(ex, 0.0), np.maximum(ey, 0.0)) + np.minimum(np.maximum(ex, ey), 0.0)


def inside_field(env: Environment, points: np.ndarray) -> np.ndarray:
    """Boolean mask of points inside the closed field rectangle ``[0, w] x [0, h]``."""
    p = _as_points(points)
    return (p[:, 0] >= 0) & (p[:, 0] <= env.width) & (p[:, 1] >= 0) & (p[:, 1] <= env.height)


def distance_to_obstacles(env: Environment, points: np.ndarray) -> np.ndarray:
    """Exact distance (m) from each point to the nearest obstacle: blocks and field walls.

    Points inside a block or outside the field get 0.
    """
    p = _as_points(points)
    d = np.minimum(_wall_distance(env, p), signed_distance_to_blocks(env, p))
    return np.maximum(d, 0.0)


def segment_distance_to_obstacles(
    env: Environment, a: np.ndarray, b: np.ndarray, *, spacing: float = 0.002
) -> np.ndarray:
    """Minimum obstacle distance (m) along each segment ``a[i] -> b[i]``.

    The segments are sampled every ``spacing`` metres (all at once); the
    result is exact up to ``spacing / 2`` because the distance field is
    1-Lipschitz.
    """
    a, b = _as_points(a), _as_points(b)
    if spacing <= 0:
        raise ValueError("`spacing` must be > 0")
    pts, owner = sample_segments(a, b, spacing)
    d = distance_to_obstacles(env, pts)
    out = np.full(len(a), np.inf)
    np.minimum.at(out, owner, d)
    return out


def sample_segments(a: np.ndarray, b: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``spacing`` m along each segment, ends included, and each point's segment index."""
    a, b = _as_points(a), _as_points(b)
    lengths = np.hypot(*(b - a).T)
    counts = np.maximum(np.ceil(lengths / spacing).astype(np.int64), 1) + 1
    owner = np.repeat(np.arange(len(a)), counts)
    starts = np.cumsum(counts) - counts
    step = np.arange(counts.sum()) - np.repeat(starts, counts)
    t = step / np.repeat(counts - 1, counts)
    pts = a[owner] + (b - a)[owner] * t[:, None]
    return pts, owner


def _segment_box_distance(
    ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray, hx: np.ndarray, hy: np.ndarray
) -> np.ndarray:
    """Exact distance (m) from segments ``a -> b`` to boxes ``[-hx, hx] x [-hy, hy]``, all in the box frame.

    0 when the segment touches or enters the box (separating-axis test on the
    box axes and the segment's normal); otherwise the smallest of the two end
    points' distances to the box and the four corners' distances to the
    segment, which is exact for two disjoint convex polygons.
    """
    dx, dy = bx - ax, by - ay
    meets = (
        (np.minimum(ax, bx) <= hx)
        & (np.maximum(ax, bx) >= -hx)
        & (np.minimum(ay, by) <= hy)
        & (np.maximum(ay, by) >= -hy)
        & (np.abs(dx * ay - dy * ax) <= hx * np.abs(dy) + hy * np.abs(dx))
    )
    best = np.minimum(_box_signed_distance(ax, ay, hx, hy), _box_signed_distance(bx, by, hx, hy))
    len2 = dx * dx + dy * dy
    inv = np.divide(1.0, len2, out=np.zeros_like(len2), where=len2 > 0)
    for sx, sy in ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)):
        cx, cy = sx * hx - ax, sy * hy - ay
        t = np.clip((cx * dx + cy * dy) * inv, 0.0, 1.0)
        np.minimum(best, np.hypot(cx - t * dx, cy - t * dy), out=best)
    return np.where(meets, 0.0, best)


# rows of (points x blocks) handled at once: bounds memory for long paths
_CHUNK_CELLS = 1 << 18


def _segments_to_blocks(env: Environment, a: np.ndarray, b: np.ndarray, both: np.ndarray | None) -> np.ndarray:
    """Exact distance (m) from each segment ``a[i] -> b[i]`` to the nearest block (0 if it meets one).

    ``both`` optionally holds the polyline ``a[0], b[0], b[1], ...`` so its
    vertices' block distances are computed once.  A segment can only be
    nearer to block ``j`` than its own end points are to their nearest block
    if ``min(sd_a, sd_b) - length / 2`` (a lower bound, the signed distance
    being 1-Lipschitz) is smaller; only those (segment, block) pairs are
    computed exactly.
    """
    centres, half, angles = block_arrays(env)
    out = np.full(len(a), np.inf)
    if len(centres) == 0 or len(a) == 0:
        return out
    step = max(1, _CHUNK_CELLS // len(centres))
    for lo in range(0, len(a), step):
        hi = min(lo + step, len(a))
        if both is not None:
            lx, ly = _block_local(both[lo : hi + 1], centres, angles)
            sd = _box_signed_distance(lx, ly, half[:, 0], half[:, 1])
            ax, ay, bx, by, sda, sdb = lx[:-1], ly[:-1], lx[1:], ly[1:], sd[:-1], sd[1:]
        else:
            ax, ay = _block_local(a[lo:hi], centres, angles)
            bx, by = _block_local(b[lo:hi], centres, angles)
            sda = _box_signed_distance(ax, ay, half[:, 0], half[:, 1])
            sdb = _box_signed_distance(bx, by, half[:, 0], half[:, 1])
        ends = np.minimum(sda, sdb)
        upper = np.maximum(ends.min(axis=1), 0.0)
        semi = 0.5 * np.hypot(*(b[lo:hi] - a[lo:hi]).T)
        rows, cols = np.nonzero((ends - semi[:, None] < upper[:, None]) & (upper[:, None] > 0))
        exact = _segment_box_distance(
            ax[rows, cols], ay[rows, cols], bx[rows, cols], by[rows, cols], half[cols, 0], half[cols, 1]
        )
        np.minimum.at(upper, rows, exact)
        out[lo:hi] = upper
    return out


def _segments_to_walls(env: Environment, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact distance (m) from each segment to the field boundary, negative when an end is outside.

    The distance to the boundary, ``min(x, w - x, y, h - y)``, is concave,
    so along a segment it is smallest at an end point.
    """

    return np.minimum(_wall_distance(env, a), _wall_distance(env, b))


def _wall_distance(env: Environment, p: np.ndarray) -> np.ndarray:
    """Signed distance (m) of points ``(N, 2)`` to the field boundary, negative outside."""
    return np.minimum(np.minimum(p[:, 0], env.width - p[:, 0]), np.minimum(p[:, 1], env.height - p[:, 1]))


def segment_clearance(env: Environment, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact clearance (m) of each segment ``a[i] -> b[i]``: its smallest distance to blocks and walls.

    Parameters
    ----------
    env : Environment
    a, b : (S, 2) or (S, 3) float arrays, m
        Segment ends (a third column is ignored).

    Returns
    -------
    (S,) float array, m
        The minimum over every point of each segment of
        :func:`distance_to_obstacles`: 0 when the segment touches or enters
        a block or leaves the field.  Exact (no sampling), unlike
        :func:`segment_distance_to_obstacles`.
    """
    a, b = _as_points(a), _as_points(b)
    if a.shape != b.shape:
        raise ValueError(f"`a` and `b` must have the same shape, got {a.shape} and {b.shape}")
    d = np.minimum(_segments_to_walls(env, a, b), _segments_to_blocks(env, a, b, None))
    return np.maximum(d, 0.0)


def polyline_clearance(env: Environment, path: np.ndarray) -> np.ndarray:
    """Exact clearance (m) of each segment of the polyline ``path`` ``(N, 2)``: ``(N - 1,)`` array.

    Same result as ``segment_clearance(env, path[:-1], path[1:])``, computing
    each vertex's block distances once.
    """
    p = _as_points(path)
    a, b = p[:-1], p[1:]
    d = np.minimum(_segments_to_walls(env, a, b), _segments_to_blocks(env, a, b, p))
    return np.maximum(d, 0.0)


def polyline_min_clearance(env: Environment, path: np.ndarray, *, chunk: int = 32) -> float:
    """Exact minimum clearance (m) over every point of the polyline ``path`` ``(N, 2)``.

    Equal to ``polyline_clearance(env, path).min()`` (or the one point's
    clearance when ``N == 1``) without computing every (segment, block)
    pair: the path is cut into runs of ``chunk`` segments, each inside its
    bounding box's circumcircle (radius ``r``); a run can only come closer
    to a block than the current best ``U`` if the signed distance from its
    box centre to the block, minus ``r``, is below ``U``.  ``U`` starts as
    the exact clearance of every run's first vertex and of the walls; only
    the segments of the runs left are measured exactly.
    """
    p = _as_points(path)
    if len(p) == 0:
        raise ValueError("`path` must have at least 1 point")
    if len(p) == 1:
        return float(distance_to_obstacles(env, p)[0])
    best = float(_wall_distance(env, p).min())
    centres, half, angles = block_arrays(env)
    if len(centres) == 0 or best <= 0:
        return max(best, 0.0)
    segs = len(p) - 1
    starts = np.arange(0, segs, chunk)
    counts = np.minimum(starts + chunk, segs) - starts
    # bounding box of each run's vertices starts[c] .. starts[c] + counts[c]
    lo = np.minimum.reduceat(p[:-1], starts, axis=0)
    hi = np.maximum.reduceat(p[:-1], starts, axis=0)
    ends = p[starts + counts]
    lo, hi = np.minimum(lo, ends), np.maximum(hi, ends)
    mid, radius = 0.5 * (lo + hi), 0.5 * np.hypot(*(hi - lo).T)
    best = min(best, float(signed_distance_to_blocks(env, p[starts]).min()))
    if best <= 0:
        return 0.0
    lx, ly = _block_local(mid, centres, angles)
    run, blk = np.nonzero(_box_signed_distance(lx, ly, half[:, 0], half[:, 1]) - radius[:, None] < best)
    if len(run):
        n = counts[run]
        first = np.cumsum(n) - n
        seg = np.repeat(starts[run], n) + np.arange(int(n.sum())) - np.repeat(first, n)
        blk = np.repeat(blk, n)
        frame = (centres[blk, 0], centres[blk, 1], np.cos(angles[blk]), np.sin(angles[blk]))
        ax, ay = _to_frame(p[seg, 0], p[seg, 1], *frame)
        bx, by = _to_frame(p[seg + 1, 0], p[seg + 1, 1], *frame)
        best = min(best, float(_segment_box_distance(ax, ay, bx, by, half[blk, 0], half[blk, 1]).min()))
    return max(best, 0.0)
