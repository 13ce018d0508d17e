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
    "sample_segments",
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
    d = p[:, None, :] - centres[None, :, :]  # (N, B, 2)
    c, s = np.cos(angles), np.sin(angles)
    # rotate into each block's frame
    lx = np.abs(c * d[..., 0] + s * d[..., 1]) - half[:, 0]
    ly = np.abs(-s * d[..., 0] + c * d[..., 1]) - half[:, 1]
    outside = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0))
    inside = np.minimum(np.maximum(lx, ly), 0.0)
    return (outside + inside).min(axis=1)


def inside_field(env: Environment, points: np.ndarray) -> np.ndarray:
    """Boolean mask of points inside the closed field rectangle ``[0, w] x [0, h]``."""
    p = _as_points(points)
    return (p[:, 0] >= 0) & (p[:, 0] <= env.width) & (p[:, 1] >= 0) & (p[:, 1] <= env.height)


def distance_to_obstacles(env: Environment, points: np.ndarray) -> np.ndarray:
    """Exact distance (m) from each point to the nearest obstacle: blocks and field walls.

    Points inside a block or outside the field get 0.
    """
    p = _as_points(points)
    walls = np.minimum.reduce([p[:, 0], env.width - p[:, 0], p[:, 1], env.height - p[:, 1]])
    d = np.minimum(walls, signed_distance_to_blocks(env, p))
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
