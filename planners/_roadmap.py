"""Compiled kernels of the PRM (:mod:`planners.prm`): k nearest neighbours, candidate edges, their collision
check and the Dijkstra query (numba).

At the paper's grid sizes (180 x 180 cells, 500 samples) a PRM solve is a few milliseconds, and almost all of
it used to be fixed per-call overhead of general-purpose routines: ``cKDTree.query`` (0.5 ms for 500 points),
``np.unique`` of the candidate pairs, gathering the segment ends, a ``coo_matrix`` -> CSR conversion and
``scipy.sparse.csgraph.dijkstra``'s validation.  These kernels compute the same things in one pass each:

- :func:`knn`: the ``k`` nearest of a point set to each query point, on a uniform bucket grid searched ring by
  ring (exact: a ring stops the search only when the k-th distance is below the distance to any unsearched
  bucket);
- :func:`free_knn_edges`: the unique pairs ``(i, j)``, ``i < j``, of each query point and its neighbours,
  kept where the exact segment test (:func:`planners._segment.segment_free`) passes;
- :func:`query_path`: start and goal joined to their ``k`` nearest nodes and each other, then Dijkstra with a
  binary heap (:mod:`heapq`) over the undirected roadmap, stopping when the goal is settled.

The neighbour sets, the edges and the shortest path are those of the former scipy pipeline (distances are
the same floating-point expressions; only exact ties, of probability zero for sampled points, could order
differently).  Imported lazily (numba loads with it).
"""

from __future__ import annotations

import heapq
import math

import numpy as np
from numba import njit

from ._segment import point_free, segment_free

_jit = njit(cache=True, nogil=True)


@_jit
def points_free(free, nx, ny, inv_h, width, height, pts):
    """``ConfigSpace.is_free`` of every point of ``pts`` ``(N, 2)`` (m): ``(N,)`` bool."""
    out = np.empty(len(pts), dtype=np.bool_)
    for i in range(len(pts)):
        out[i] = point_free(free, nx, ny, inv_h, width, height, pts[i, 0], pts[i, 1])
    return out


@_jit
def _reach_at(nx, ny, inv_h, reach, x, y):
    """A lower bound (cells) on the distance from (x, y) (m) to any non-free cell: ``reach`` of its cell less
    its distance from the cell's centre; -1 outside the grid."""
    u = x * inv_h
    v = y * inv_h
    fx = math.floor(u)
    fy = math.floor(v)
    if 0 <= fx < nx and 0 <= fy < ny:
        return reach[int(fy) * nx + int(fx)] - math.hypot(u - fx - 0.5, v - fy - 0.5)
    return -1.0


@_jit
def edge_free(free, nx, ny, inv_h, width, height, reach, ax, ay, bx, by):
    """:func:`planners._segment.segment_free` of (ax, ay) -> (bx, by) (m), with a quick accept.

    ``reach[c]`` (cells, float32) is a lower bound on the distance from the centre of free cell ``c`` to any non-free
    cell, less its distance from the centre for a point in it (:func:`_reach_at`), so a piece of the segment no longer than the ``reach`` of its two ends' cells together lies in two
    discs touching no non-free cell.  When the segment, or its halves, quarters or eighths (at least 4 cells
    long) are all covered so, every cell the exact test would look at is free; otherwise the exact test decides.
    """
    length = math.hypot((bx - ax) * inv_h, (by - ay) * inv_h)  # cells
    ra = _reach_at(nx, ny, inv_h, reach, ax, ay)
    rb = _reach_at(nx, ny, inv_h, reach, bx, by)
    if ra + rb > length:
        return True
    m = 2
    while m <= 8 and length >= 4.0 * m:  # 2, 4, 8 equal pieces, each at least 4 cells long
        piece = length / m
        r0 = ra
        covered = True
        for i in range(1, m + 1):
            t = i / m
            r1 = rb if i == m else _reach_at(nx, ny, inv_h, reach, ax + (bx - ax) * t, ay + (by - ay) * t)
            if r0 + r1 <= piece:
                covered = False
                break
            r0 = r1
        if covered:
            return True
        m *= 2
    return segment_free(free, nx, ny, inv_h, width, height, ax, ay, bx, by)


@_jit
def _insert(bd, bi, cnt, d, j):
    """Insert distance ``d`` of point ``j`` into the ascending lists ``bd``/``bi`` holding ``cnt`` of at most
    ``len(bd)`` entries; returns the new count."""
    k = len(bd)
    if cnt < k:
        pos = cnt
        cnt += 1
    elif d < bd[k - 1]:
        pos = k - 1
    else:
        return cnt
    while pos > 0 and bd[pos - 1] > d:
        bd[pos] = bd[pos - 1]
        bi[pos] = bi[pos - 1]
        pos -= 1
    bd[pos] = d
    bi[pos] = j
    return cnt


@_jit
def knn(pts, n, qs, k, width, height):
    """Indices ``(Q, min(k, n))`` of the nearest of ``pts[:n]`` (m) to each point of ``qs`` ``(Q, 2)`` (m),
    nearest first; the points lie in the ``width`` x ``height`` field (query points may lie anywhere)."""
    k = min(k, n)
    nq = len(qs)
    out = np.empty((nq, k), dtype=np.int64)
    if k == 0:
        return out
    # buckets of about two points each
    side = math.sqrt(width * height * 2.0 / n)
    gx = min(max(int(width / side), 1), 1024)
    gy = min(max(int(height / side), 1), 1024)
    cw = width / gx
    ch = height / gy
    cell = np.empty(n, dtype=np.int64)
    start = np.zeros(gx * gy + 1, dtype=np.int64)
    for i in range(n):
        cx = min(max(int(pts[i, 0] / cw), 0), gx - 1)
        cy = min(max(int(pts[i, 1] / ch), 0), gy - 1)
        cell[i] = cy * gx + cx
        start[cell[i] + 1] += 1
    for c in range(gx * gy):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, dtype=np.int64)
    for i in range(n):
        items[fill[cell[i]]] = i
        fill[cell[i]] += 1
    bd = np.empty(k)
    bi = np.empty(k, dtype=np.int64)
    for q in range(nq):
        x = qs[q, 0]
        y = qs[q, 1]
        cx = min(max(int(x / cw), 0), gx - 1) if x > 0 else 0
        cy = min(max(int(y / ch), 0), gy - 1) if y > 0 else 0
        cnt = 0
        r = 0
        while True:
            x0, x1, y0, y1 = cx - r, cx + r, cy - r, cy + r
            for by in range(max(y0, 0), min(y1, gy - 1) + 1):
                edge_row = by == y0 or by == y1
                step = 1 if edge_row else x1 - x0
                bx = x0
                while bx <= x1:
                    if 0 <= bx < gx:
                        c = by * gx + bx
                        for t in range(start[c], start[c + 1]):
                            j = items[t]
                            dx = x - pts[j, 0]
                            dy = y - pts[j, 1]
                            d = dx * dx + dy * dy
                            if cnt < k or d < bd[k - 1]:  # insert into the ascending list (inline: faster)
                                if cnt < k:
                                    pos = cnt
                                    cnt += 1
                                else:
                                    pos = k - 1
                                while pos > 0 and bd[pos - 1] > d:
                                    bd[pos] = bd[pos - 1]
                                    bi[pos] = bi[pos - 1]
                                    pos -= 1
                                bd[pos] = d
                                bi[pos] = j
                    if step == 0:
                        break
                    bx += step
            done = x0 <= 0 and y0 <= 0 and x1 >= gx - 1 and y1 >= gy - 1
            if done:
                break
            if cnt == k:
                # the nearest any unsearched bucket can be: the searched square's nearest open side
                bound = math.inf
                if x0 > 0:
                    bound = min(bound, x - x0 * cw)
                if x1 < gx - 1:
                    bound = min(bound, (x1 + 1) * cw - x)
                if y0 > 0:
                    bound = min(bound, y - y0 * ch)
                if y1 < gy - 1:
                    bound = min(bound, (y1 + 1) * ch - y)
                if bound > 0 and bd[k - 1] < bound * bound:
                    break
            r += 1
        for a in range(k):
            out[q, a] = bi[a]
    return out


@_jit
def free_knn_edges(free, nx, ny, inv_h, width, height, reach, pts, nb, offset):
    """The unique free edges ``(E, 2)`` (``i < j``) joining each query point ``offset + q`` of ``pts`` to its
    neighbours ``nb[q]`` (itself excepted): a pair of two query points that list each other is taken once."""
    nq, k = nb.shape
    out = np.empty((nq * k, 2), dtype=np.int64)
    e = 0
    for q in range(nq):
        i = q + offset
        for a in range(k):
            j = nb[q, a]
            if j == i:
                continue
            if offset <= j < offset + nq and j < i:
                listed = False
                for b in range(k):
                    if nb[j - offset, b] == i:
                        listed = True
                        break
                if listed:
                    continue  # the pair came with j
            lo = min(i, j)
            hi = max(i, j)
            if edge_free(free, nx, ny, inv_h, width, height, reach, pts[lo, 0], pts[lo, 1], pts[hi, 0], pts[hi, 1]):
                out[e, 0] = lo
                out[e, 1] = hi
                e += 1
    return out[:e].copy()


@_jit
def query_path(free, nx, ny, inv_h, width, height, reach, nodes, edges, sx, sy, gx, gy, k):
    """The shortest path from (sx, sy) to (gx, gy) (m) over the roadmap ``nodes`` ``(M, 2)`` / ``edges``
    ``(E, 2)``, with start and goal joined to their ``k`` nearest nodes and to each other where the segment is
    free: the point indices along it (start ``M``, goal ``M + 1``), or an empty array when they do not connect."""
    m = len(nodes)
    pts = np.empty((m + 2, 2))
    pts[:m] = nodes
    pts[m, 0] = sx
    pts[m, 1] = sy
    pts[m + 1, 0] = gx
    pts[m + 1, 1] = gy
    kk = min(k, m)
    # start and goal: their k nearest nodes (brute force: two queries)
    extra = np.empty((2 * kk + 1, 2), dtype=np.int64)
    ne = 0
    bd = np.empty(kk)
    bi = np.empty(kk, dtype=np.int64)
    for s in range(2):
        cnt = 0
        px = pts[m + s, 0]
        py = pts[m + s, 1]
        for j in range(m):
            dx = px - pts[j, 0]
            dy = py - pts[j, 1]
            d = dx * dx + dy * dy
            if cnt < kk or d < bd[kk - 1]:
                cnt = _insert(bd, bi, cnt, d, j)
        for a in range(cnt):
            j = bi[a]
            if edge_free(free, nx, ny, inv_h, width, height, reach, pts[j, 0], pts[j, 1], px, py):
                extra[ne, 0] = j
                extra[ne, 1] = m + s
                ne += 1
    if edge_free(free, nx, ny, inv_h, width, height, reach, sx, sy, gx, gy):
        extra[ne, 0] = m
        extra[ne, 1] = m + 1
        ne += 1
    # undirected adjacency (CSR) with Euclidean weights
    n = m + 2
    ptr = np.zeros(n + 1, dtype=np.int64)
    ed = len(edges)
    for e in range(ed):
        ptr[edges[e, 0] + 1] += 1
        ptr[edges[e, 1] + 1] += 1
    for e in range(ne):
        ptr[extra[e, 0] + 1] += 1
        ptr[extra[e, 1] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    fill = ptr[:-1].copy()
    adj = np.empty(ptr[n], dtype=np.int64)
    wt = np.empty(ptr[n])
    for e in range(ed + ne):
        if e < ed:
            u = edges[e, 0]
            v = edges[e, 1]
        else:
            u = extra[e - ed, 0]
            v = extra[e - ed, 1]
        # zero-length edges would vanish from a sparse matrix; keep them tiny, as before
        w = max(math.hypot(pts[u, 0] - pts[v, 0], pts[u, 1] - pts[v, 1]), 1e-12)
        adj[fill[u]] = v
        wt[fill[u]] = w
        fill[u] += 1
        adj[fill[v]] = u
        wt[fill[v]] = w
        fill[v] += 1
    # Dijkstra from the start with a binary heap (heapq, lazy deletion), stopping at the goal
    dist = np.full(n, np.inf)
    pred = np.full(n, -1, dtype=np.int64)
    done = np.zeros(n, dtype=np.bool_)
    dist[m] = 0.0
    heap = [(0.0, m)]
    goal = m + 1
    while len(heap) > 0:
        d, u = heapq.heappop(heap)
        if done[u]:
            continue
        done[u] = True
        if u == goal:
            break
        for t in range(ptr[u], ptr[u + 1]):
            v = adj[t]
            nd = d + wt[t]
            if nd < dist[v]:
                dist[v] = nd
                pred[v] = u
                heapq.heappush(heap, (nd, v))
    if not done[goal]:
        return np.empty(0, dtype=np.int64)
    length = 1
    v = goal
    while v != m:
        v = pred[v]
        length += 1
    order = np.empty(length, dtype=np.int64)
    v = goal
    for i in range(length - 1, -1, -1):
        order[i] = v
        v = pred[v]
    return order


_warm = False


def warm() -> None:
    """Load (or compile) every kernel once per process, on a tiny problem, so that a planner's time budget
    does not pay for it."""
    global _warm
    if _warm:
        return
    free = np.ones(4, dtype=np.uint8)
    reach = np.ones(4, dtype=np.float32)  # the dtype of _Kernels.reach: one compiled signature
    pts = np.array([[0.5, 0.5], [1.5, 1.5], [0.5, 1.5]])
    args = (free, 2, 2, 1.0, 2.0, 2.0)
    points_free(*args, pts)
    nb = knn(pts, 3, pts, 2, 2.0, 2.0)
    edges = free_knn_edges(*args, reach, pts, nb, 0)
    query_path(*args, reach, pts, edges, 0.25, 0.25, 1.75, 1.75, 2)
    _warm = True
