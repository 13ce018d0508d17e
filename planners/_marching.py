"""Compiled kernels of :class:`planners.fast_marching.FrontMarch`: scikit-fmm's travel-time scheme, resumable.

Imported lazily (numba loads only where a fast-marching planner runs: the
server and the SDK import :mod:`planners` without it).  The kernels work on
grids padded by two masked cells, flattened: ``k = (i + 2) * W + (j + 2)``
for cell ``(i, j)`` of an ``(ny, nx)`` grid, ``W = nx + 4``; the padding
spares every bounds check, and the arrival-time array is the one the
descent reads (frozen cells hold their value, every other cell ``BIG``).

What reproduces ``skfmm.travel_time(phi, speed, dx=h)`` (order 2, no narrow
band, no periodic axes) value for value, as worked out from scikit-fmm
2025.06.23's documented behaviour, experiments against it and the
disassembly of its installed extension (no source was copied):

- the initial front: every free cell whose 4-neighbour across the zero level
  set of ``phi`` is free gets ``|d / speed|``, ``d`` the distance to the level
  set from linear interpolation along each axis (``1 / d^2`` summed over the
  axes); a cell with ``phi == 0`` gets 0; the far cells next to it are
  computed and queued, in raster order;
- a cell's update solves ``sum_axes a (T - u)^2 = 1 / speed^2`` over the axes
  with a frozen neighbour: ``u`` the smaller frozen neighbour (the ``-1`` side
  is looked at first and kept on ties) and, when the neighbour beyond it is
  frozen and no larger, the second-order ``u = (4 v1 - v2) / 3`` with
  ``a = 9 / 4``; ``v2`` is negated when ``phi`` changes sign between the three
  cells, and is *not* forgotten when the ``+1`` side then gives a smaller
  ``v1`` without a second neighbour of its own; the arithmetic in the same
  order as scikit-fmm's, so the roundings agree;
- a negative discriminant falls back to the smaller of the one-axis
  solutions;
- speeds below the machine epsilon are masked (by the caller);
- accepting takes the smallest tentative value *and every other cell with
  exactly that value* before any neighbour is updated; then, per accepted cell,
  per axis, per side (``-1``, ``+1``): the neighbour is updated (queued when
  far), and when it is frozen, the cell beyond it is updated if tentative;
  an update that returns exactly 0 changes nothing.

Because ties are accepted together and an update depends only on the frozen
cells' values, the values do not depend on how the priority queue is built or
breaks ties (a 4-ary heap here, a binary one in scikit-fmm); nor on skipping
recomputations that provably return the stored value (the accepted cell is
no input of that neighbour's update), which scikit-fmm performs.
``tests/test_fast_marching.py`` checks the equality on built-in and random
problems.

Early termination: :func:`march` stops as soon as every *wanted* cell is
frozen (after finishing the batch it accepted), keeping its queue, so a later
call continues exactly where it stopped.  What makes it about 4 times as fast
per cell as scikit-fmm: docs/performance.md.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

FAR, NARROW, FROZEN, MASK = 0, 1, 2, 3
MAXD = 1.7976931348623157e308  # scikit-fmm's "no value"
BIG = 1e30  # arrival time standing for "blocked" in the descent's array (see fast_marching._BIG)
THIRD = 1.0 / 3.0

_jit = njit(cache=True, error_model="numpy", nogil=True)
U = np.uint64  # an array index that numba need not check for wrapping around


@_jit
def init_grid(free, flag, t):
    """Padded flags (far where ``free``, masked elsewhere and on the border) and arrival times (``BIG``)."""
    ny, nx = free.shape
    W = nx + 4
    flag[:] = MASK
    t[:] = BIG
    for i in range(ny):
        row = (i + 2) * W + 2
        for j in range(nx):
            if free[i, j]:
                flag[row + j] = FAR


@_jit
def start_front(W, flag, t, sgn, h, phi_win, speed_win, k0, seeds):
    """The initial front from the zero level set of ``phi``, given on a window around the goal.

    ``phi_win`` (and ``speed_win``) are ``phi`` (the speed) on the window whose
    top-left cell has padded index ``k0``; outside the window ``phi > 0``, so no
    cell there borders the level set.  Freezes the bordering cells with
    ``|d / speed|``, codes the sign of ``phi`` in ``sgn`` (0 positive, 1
    negative, 2 zero), and writes the far cells next to a frozen one to
    ``seeds`` in raster order (scikit-fmm's narrow band, which :func:`march`
    computes first).  Returns how many, or -1 when no cell borders the level
    set (scikit-fmm: "no zero level set").
    """
    r, c = phi_win.shape
    dist = np.zeros((r, c))
    frozen = np.zeros((r, c), dtype=np.bool_)
    for i in range(r):
        for j in range(c):
            ph = phi_win[i, j]
            sgn[k0 + i * W + j] = 1 if ph < 0.0 else (2 if ph == 0.0 else 0)
    nfrozen = 0
    for i in range(r):
        for j in range(c):
            if flag[k0 + i * W + j] == MASK:
                continue
            ph = phi_win[i, j]
            if ph == 0.0:
                frozen[i, j] = True
                nfrozen += 1
                continue
            l0 = 0.0
            l1 = 0.0
            borders = False
            for axis in range(2):
                for d in (-1, 1):
                    ii = i + d if axis == 0 else i
                    jj = j if axis == 0 else j + d
                    if ii < 0 or ii >= r or jj < 0 or jj >= c or flag[k0 + ii * W + jj] == MASK:
                        continue
                    pn = phi_win[ii, jj]
                    if ph * pn < 0.0:
                        borders = True
                        dd = h * ph / (ph - pn)
                        if axis == 0:
                            if l0 == 0.0 or l0 > dd:
                                l0 = dd
                        elif l1 == 0.0 or l1 > dd:
                            l1 = dd
            if borders:
                dsum = 0.0
                if l0 > 0.0:
                    dsum += 1.0 / l0 / l0
                if l1 > 0.0:
                    dsum += 1.0 / l1 / l1
                dist[i, j] = -math.sqrt(1.0 / dsum) if ph < 0.0 else math.sqrt(1.0 / dsum)
                frozen[i, j] = True
                nfrozen += 1
    if nfrozen == 0:
        return -1
    for i in range(r):
        for j in range(c):
            if frozen[i, j]:
                k = k0 + i * W + j
                flag[k] = FROZEN
                t[k] = abs(dist[i, j] / speed_win[i, j])
    n = 0
    for i in range(-1, r + 1):  # frozen cells lie in the window, so their neighbours in the window grown by one
        for j in range(-1, c + 1):
            k = k0 + i * W + j
            if flag[k] == FAR and (flag[k - W] == FROZEN or flag[k + W] == FROZEN or flag[k - 1] == FROZEN
                                   or flag[k + 1] == FROZEN):
                seeds[n] = k
                n += 1
    return n


@_jit
def march(W, flag, t, sgn, sgn_lo, sgn_hi, inv_s2, unit, idx2, hkey, hcell, pos, state, want, batch, seeds):
    """Accept cells until every wanted cell is frozen (or the front has stopped); resumable.

    ``t`` holds the arrival times of the frozen cells, ``BIG`` elsewhere (the
    updates read only those; tentative values live in the heap, as keys: every
    arrival time is >= 0).  ``state`` = [heap size, wanted cells not yet
    accepted, cells accepted, seeds computed];
    ``want[k]`` is 1 for a wanted cell and is cleared when it is accepted.
    ``inv_s2`` is ``1 / speed^2`` (unused when ``unit``); the cells with a
    non-zero ``sgn`` lie in padded indices ``sgn_lo..sgn_hi``.  The heap is
    4-ary, its root at index 3 so that each node's four children (from index
    ``4 i - 8``) share a 32-byte block: ``(hkey, hcell)[3..n+3)``, with
    ``hkey[n+3..n+6)`` = ``inf`` as sentinels, and ``pos`` each queued cell's
    index.

    Written as one loop with one copy of the update and of each heap operation
    (helper functions taking arrays would cost reference counting on every
    call), arrays indexed with unsigned integers (no negative-index
    wraparound), and the updates of an accepted cell's neighbours computed
    before any of them is queued, so that their square roots and divisions
    overlap.
    """
    n = state[0]
    remaining = state[1]
    accepted = state[2]
    si = state[3]
    nseeds = seeds.shape[0]
    A2 = idx2 * 2.25
    B2 = (idx2 + idx2) * 2.25
    B1 = idx2 + idx2
    near_lo = sgn_lo - 2 * W - 2
    near_hi = sgn_hi + 2 * W + 2
    tgt = np.empty(4, dtype=np.int64)  # the cells to update, their mode (0 seed, 1 far, 2 tentative), value
    tmode = np.empty(4, dtype=np.int64)
    tval = np.empty(4)
    b = 0
    nb = 0
    while True:
        # ---- the cells to update: a seed, or the neighbours of the next accepted cell ----
        nt = 0
        if si < nseeds:
            tgt[0] = seeds[U(si)]
            tmode[0] = 0  # pushed whatever the update gives
            nt = 1
            si += 1
        else:
            if b == nb:
                if n == 0 or remaining <= 0:
                    break
                # accept the smallest value and every other cell with exactly that value
                value = hkey[3]
                nb = 0
                while n > 0 and hkey[3] == value:
                    k = hcell[3]
                    flag[U(k)] = FROZEN
                    t[U(k)] = value
                    batch[U(nb)] = k
                    nb += 1
                    if want[U(k)]:
                        want[U(k)] = 0
                        remaining -= 1
                    n -= 1
                    lk = hkey[U(n + 3)]
                    lc = hcell[U(n + 3)]
                    hkey[U(n + 3)] = np.inf
                    if n > 0:
                        i = 3
                        ch = 4
                        while ch < n + 3:  # the hole down to a leaf along the smaller children
                            k0 = hkey[U(ch)]
                            k1 = hkey[U(ch + 1)]
                            k2 = hkey[U(ch + 2)]
                            k3 = hkey[U(ch + 3)]
                            l1 = k1 < k0
                            ca = ch + np.int64(l1)
                            ka = min(k0, k1)
                            l3 = k3 < k2
                            cb = ch + 2 + np.int64(l3)
                            kb = min(k2, k3)
                            lb = kb < ka
                            ch = ca + np.int64(lb) * (cb - ca)
                            hkey[U(i)] = min(ka, kb)
                            hcell[U(i)] = hcell[U(ch)]
                            pos[U(hcell[U(i)])] = i
                            i = ch
                            ch = 4 * i - 8
                        while i > 3:  # then the last entry up from there
                            par = (i + 8) >> 2
                            if lk < hkey[U(par)]:
                                hkey[U(i)] = hkey[U(par)]
                                hcell[U(i)] = hcell[U(par)]
                                pos[U(hcell[U(i)])] = i
                                i = par
                            else:
                                break
                        hkey[U(i)] = lk
                        hcell[U(i)] = lc
                        pos[U(lc)] = i
                accepted += nb
                b = 0
            c = batch[U(b)]
            b += 1
            tc = t[U(c)]
            for d in range(4):
                s = W if d < 2 else 1  # axis 0 then 1, each side -1 then +1
                if d == 0 or d == 2:
                    s = -s
                m = c + s
                fm = flag[U(m)]
                if fm == FROZEN:
                    # c enters the update of the tentative cell beyond m only as its second-order neighbour,
                    # when no larger than m (otherwise that update returns its stored value: skipped)
                    p = m + s
                    if flag[U(p)] != NARROW:
                        continue
                    tm = t[U(m)]
                    if not ((tc <= tm and tm >= 0.0) or (tc >= tm and tm <= 0.0)):
                        continue
                    tmode[nt] = 2
                elif fm == NARROW:
                    # c is m's +1 side when s < 0: no input when m's -1 side is frozen and no larger
                    if s < 0 and flag[U(m + s)] == FROZEN and abs(t[U(m + s)]) <= abs(tc):
                        continue
                    p = m
                    tmode[nt] = 2
                elif fm == FAR:
                    p = m
                    tmode[nt] = 1
                else:
                    continue
                tgt[nt] = p
                nt += 1
        # ---- scikit-fmm's second-order update of each ----
        # (every arrival time is >= 0, so its comparisons of absolute values and its two-sided test for
        # the second neighbour reduce to the plain ones below)
        for e in range(nt):
            p = tgt[e]
            o0 = 0
            o1 = 0
            u0 = 0.0
            u1 = 0.0
            for ax in range(2):
                s = W if ax == 0 else 1
                tl = t[U(p - s)]  # BIG when not frozen
                tr = t[U(p + s)]
                tl2 = t[U(p - 2 * s)]
                okl = tl < BIG and tl2 < BIG and (tl2 <= tl or tl == 0.0)
                if tl <= tr:  # the -1 side (or none): scikit-fmm looks at it first and keeps it on a tie
                    v1 = tl if tl < BIG else MAXD
                    v2 = tl2 if okl else MAXD
                    side = -1
                else:
                    v1 = tr
                    tr2 = t[U(p + 2 * s)]
                    if tr2 < BIG and (tr2 <= tr or tr == 0.0):
                        v2 = tr2
                        side = 1
                    else:  # the -1 side's second neighbour stays (scikit-fmm does not reset it)
                        v2 = tl2 if okl else MAXD
                        side = -1
                if v2 < MAXD:
                    if near_lo <= p <= near_hi:  # phi changes sign: scikit-fmm negates v2
                        a2 = sgn[U(p + 2 * side * s)]
                        a1 = sgn[U(p + side * s)]
                        a0 = sgn[U(p)]
                        if ((a2 == 1 and a1 == 0) or (a2 == 0 and a1 == 1)
                                or (a2 == 1 and a0 == 0) or (a2 == 0 and a0 == 1)):
                            v2 = -v2
                    o = 2
                    u = (4.0 * v1 - v2) * THIRD
                elif v1 < MAXD:
                    o = 1
                    u = v1
                else:
                    o = 0
                    u = 0.0
                if ax == 0:
                    o0 = o
                    u0 = u
                else:
                    o1 = o
                    u1 = u
            inv = 1.0 if unit else inv_s2[U(p)]
            # the quadratic over both axes, in scikit-fmm's order of operations (an axis without a term adds
            # exact zeros: the same roundings)
            if o0 == 2:
                a0 = A2
                b0 = B2 * u0
                c0 = (u0 * u0) * A2
            elif o0 == 1:
                a0 = idx2
                b0 = B1 * u0
                c0 = idx2 * (u0 * u0)
            else:
                a0 = 0.0
                b0 = 0.0
                c0 = 0.0
            if o1 == 2:
                a1 = A2
                b1 = B2 * u1
                c1 = (u1 * u1) * A2
            elif o1 == 1:
                a1 = idx2
                b1 = B1 * u1
                c1 = idx2 * (u1 * u1)
            else:
                a1 = 0.0
                b1 = 0.0
                c1 = 0.0
            a = a0 + a1
            bb = (0.0 - b0) - b1
            cq = (c0 + c1) - inv
            det = bb * bb - (4.0 * a) * cq
            if det >= 0.0:
                r = ((math.sqrt(det) - bb) * 0.5) / a
            else:
                # the smaller of the solutions leaving one axis out (axis 0 first; one that fails too is
                # +inf, on which scikit-fmm would raise: a one-axis discriminant is 4 a / speed^2 > 0)
                bb = 0.0 - b1
                cq = c1 - inv
                det = bb * bb - (4.0 * a1) * cq
                r1 = ((math.sqrt(det) - bb) * 0.5) / a1 if det >= 0.0 else np.inf
                bb = 0.0 - b0
                cq = c0 - inv
                det = bb * bb - (4.0 * a0) * cq
                r0 = ((math.sqrt(det) - bb) * 0.5) / a0 if det >= 0.0 else np.inf
                r = r0 if r1 > r0 else r1
            tval[e] = r
        # ---- store and queue them ----
        for e in range(nt):
            p = tgt[e]
            r = tval[e]
            mode = tmode[e]
            if mode != 0 and r == 0.0:
                continue  # scikit-fmm: an update of exactly 0 changes nothing
            key = r
            if mode == 2:
                i = pos[U(p)]
                old = hkey[U(i)]
                if key > old:
                    while True:
                        ch = 4 * i - 8
                        if ch >= n + 3:
                            break
                        cm = ch
                        for e2 in range(1, 4):
                            if hkey[U(ch + e2)] < hkey[U(cm)]:
                                cm = ch + e2
                        ch = cm
                        if hkey[U(ch)] < key:
                            hkey[U(i)] = hkey[U(ch)]
                            hcell[U(i)] = hcell[U(ch)]
                            pos[U(hcell[U(i)])] = i
                            i = ch
                        else:
                            break
                    hkey[U(i)] = key
                    hcell[U(i)] = p
                    pos[U(p)] = i
                    continue
                if not key < old:
                    continue
            else:
                flag[U(p)] = NARROW
                i = n + 3
                hkey[U(n + 6)] = np.inf
                n += 1
            while i > 3:
                par = (i + 8) >> 2
                if key < hkey[U(par)]:
                    hkey[U(i)] = hkey[U(par)]
                    hcell[U(i)] = hcell[U(par)]
                    pos[U(hcell[U(i)])] = i
                    i = par
                else:
                    break
            hkey[U(i)] = key
            hcell[U(i)] = p
            pos[U(p)] = i
    state[0] = n
    state[1] = remaining
    state[2] = accepted
    state[3] = si


@_jit
def want_band(flag, W, H, cells, radius, want):
    """Mark as wanted every free, not yet frozen cell within ``radius`` (Chebyshev) of the padded ``cells``.

    Returns how many cells were newly marked.
    """
    m = 0
    for q in range(cells.shape[0]):
        k = cells[q]
        i = k // W
        j = k - i * W
        for ii in range(max(i - radius, 0), min(i + radius + 1, H)):
            for jj in range(max(j - radius, 0), min(j + radius + 1, W)):
                kk = ii * W + jj
                f = flag[kk]
                if (f == FAR or f == NARROW) and not want[kk]:
                    want[kk] = 1
                    m += 1
    return m
