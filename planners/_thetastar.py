"""Theta*'s search, compiled (numba): :func:`planners.anyangle.theta_star` calls :func:`search`.  Imported lazily."""

from __future__ import annotations

import heapq
import math

import numpy as np
from numba import njit

from ._segment import segment_free


@njit(cache=True, nogil=True)
def _pos(i, nx, h, s_idx, g_idx, sx, sy, gx, gy):  # type: ignore[no-untyped-def]
    """Position (m) of vertex ``i``: its cell centre, or the start or goal in their cells."""
    if i == s_idx:
        return sx, sy
    if i == g_idx:
        return gx, gy
    return (i % nx + 0.5) * h, (i // nx + 0.5) * h


@njit(cache=True, nogil=True)
def search(free, nx, ny, h, width, height, sx, sy, gx, gy, s_idx, g_idx):  # type: ignore[no-untyped-def]
    """Theta* from cell ``s_idx`` (at the start, m) to ``g_idx`` (at the goal) over the flat uint8 ``free`` of
    ``nx`` x ``ny`` cells of ``h`` m: the path ``(N, 2)`` (m; empty when unreachable) and the cells expanded."""
    n = nx * ny
    inv_h = 1.0 / h
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.uint8)
    g[s_idx] = 0.0
    parent[s_idx] = s_idx
    heap = [(math.hypot(gx - sx, gy - sy), s_idx)]
    expanded = 0
    while len(heap) > 0:
        _, u = heapq.heappop(heap)
        if closed[u]:
            continue
        closed[u] = 1
        expanded += 1
        if u == g_idx:
            break
        ux, uy = _pos(u, nx, h, s_idx, g_idx, sx, sy, gx, gy)
        p = parent[u]
        px, py = _pos(p, nx, h, s_idx, g_idx, sx, sy, gx, gy)
        cx, cy = u % nx, u // nx
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                if dx == 0 and dy == 0:
                    continue
                vx_i, vy_i = cx + dx, cy + dy
                if vx_i < 0 or vx_i >= nx or vy_i < 0 or vy_i >= ny:
                    continue
                v = vy_i * nx + vx_i
                if closed[v] or free[v] == 0:
                    continue
                vx, vy = _pos(v, nx, h, s_idx, g_idx, sx, sy, gx, gy)
                if p != u and segment_free(free, nx, ny, inv_h, width, height, px, py, vx, vy):
                    cand, via = g[p] + math.hypot(vx - px, vy - py), p
                elif segment_free(free, nx, ny, inv_h, width, height, ux, uy, vx, vy):
                    cand, via = g[u] + math.hypot(vx - ux, vy - uy), u
                else:
                    continue
                if cand < g[v]:
                    g[v] = cand
                    parent[v] = via
                    heapq.heappush(heap, (cand + math.hypot(gx - vx, gy - vy), v))
    if not closed[g_idx]:
        return np.zeros((0, 2)), expanded
    count = 1
    i = g_idx
    while i != s_idx:
        i = parent[i]
        count += 1
    out = np.empty((count, 2))
    i = g_idx
    for k in range(count - 1, -1, -1):
        out[k, 0], out[k, 1] = _pos(i, nx, h, s_idx, g_idx, sx, sy, gx, gy)
        i = parent[i]
    return out, expanded
