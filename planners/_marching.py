"""Compiled kernels of :class:`planners.fast_marching.FrontMarch`: scikit-fmm's travel-time scheme, resumable.

Imported lazily (numba loads only where a fast-marching planner runs: the
server and the SDK import :mod:`planners` without it).  The kernels work on
grids padded by two masked cells, flattened: ``k = (i + 2) * W + (j + 2)``
for cell ``(i, j)`` of an ``(ny, nx)`` grid, ``W = nx + 4``; the padding
spares every bounds check, and the arrival-time array is the one the
descent reads (blocked cells hold ``BIG``).

What reproduces ``skfmm.travel_time(phi, speed, dx=h)`` (order 2, no narrow
band, no periodic axes), value for value (scikit-fmm 2025.06.23, read from
its behaviour and its compiled marcher):

- the initial front: every free cell whose 4-neighbour across the zero level
  set of ``phi`` is free gets ``|d / speed|``, ``d`` the distance to the level
  set from linear interpolation along each axis (``1 / d^2`` summed over the
  axes); a cell with ``phi == 0`` gets 0;
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
- accepting takes the smallest tentative value *and every other cell with
  exactly that value* before any neighbour is updated; then, per accepted cell,
  per axis, per side (``-1``, ``+1``): the neighbour is updated (pushed when
  far), and when it is frozen, the cell beyond it is updated if tentative;
  an update that returns exactly 0 changes nothing.

Because ties are accepted together and an update depends only on which cells
are frozen, the values do not depend on how the priority queue breaks ties;
so the kernel skips recomputations that provably return the stored value
(the accepted cell is no input of the neighbour's update), which scikit-fmm
performs.  ``tests/test_planners_fast_marching.py`` checks equality with
scikit-fmm on built-in problems and random grids.

Early termination: :func:`march` stops as soon as every *wanted* cell is
frozen (after finishing the batch it accepted), keeping the heap, so a later
call continues exactly where it stopped.
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


@_jit
def _axis(p, s, flag, t, sgn):
    """One axis' term of the update of cell ``p`` (stride ``s``): (order 0/1/2, value u)."""
    v1 = MAXD
    v2 = MAXD
    n = p - s
    if flag[n] == FROZEN:
        tn = t[n]
        if abs(v1) > abs(tn):
            v1 = tn
            n2 = p - 2 * s
            if flag[n2] == FROZEN:
                d2 = t[n2]
                if (d2 <= v1 and v1 >= 0.0) or (d2 >= v1 and v1 <= 0.0):
                    v2 = d2
                    if sgn[n2] | sgn[n] | sgn[p]:
                        if _opposite(sgn[n2], sgn[n]) or _opposite(sgn[n2], sgn[p]):
                            v2 = -v2
    n = p + s
    if flag[n] == FROZEN:
        tn = t[n]
        if abs(v1) > abs(tn):
            v1 = tn
            n2 = p + 2 * s
            if flag[n2] == FROZEN:
                d2 = t[n2]
                if (d2 <= v1 and v1 >= 0.0) or (d2 >= v1 and v1 <= 0.0):
                    v2 = d2
                    if sgn[n2] | sgn[n] | sgn[p]:
                        if _opposite(sgn[n2], sgn[n]) or _opposite(sgn[n2], sgn[p]):
                            v2 = -v2
    if v2 < MAXD:
        return 2, (4.0 * v1 - v2) * THIRD
    if v1 < MAXD:
        return 1, v1
    return 0, 0.0


@_jit
def _opposite(a, b):
    """Whether phi's signs coded ``a`` and ``b`` (0 positive, 1 negative, 2 zero) have a negative product."""
    return (a == 1 and b == 0) or (a == 0 and b == 1)


@_jit
def _solve(o0, u0, o1, u1, inv_s2, idx2):
    """(solved, larger root) of the update's quadratic over the axes with ``o > 0`` (NaN for none, as scikit-fmm)."""
    a = 0.0
    b = 0.0
    c = 0.0
    if o0 == 2:
        a += idx2 * 2.25
        b -= (idx2 + idx2) * 2.25 * u0
        c += (u0 * u0) * (idx2 * 2.25)
    elif o0 == 1:
        a += idx2
        b -= (idx2 + idx2) * u0
        c += idx2 * (u0 * u0)
    if o1 == 2:
        a += idx2 * 2.25
        b -= (idx2 + idx2) * 2.25 * u1
        c += (u1 * u1) * (idx2 * 2.25)
    elif o1 == 1:
        a += idx2
        b -= (idx2 + idx2) * u1
        c += idx2 * (u1 * u1)
    c -= inv_s2
    det = b * b - (4.0 * a) * c
    if det >= 0.0:
        return True, ((math.sqrt(det) - b) * 0.5) / a
    return False, 0.0  # a negative (or NaN) discriminant


@_jit
def _update(p, W, flag, t, sgn, speed, unit, idx2):
    """scikit-fmm's second-order travel-time update of cell ``p``."""
    o0, u0 = _axis(p, W, flag, t, sgn)
    o1, u1 = _axis(p, 1, flag, t, sgn)
    if unit:
        inv_s2 = 1.0
    else:
        s = speed[p]
        inv_s2 = 1.0 / (s * s)
    ok, r = _solve(o0, u0, o1, u1, inv_s2, idx2)
    if not ok:
        # the smaller of the solutions leaving one axis out, axis 0 left out first; one that fails too is
        # +inf (one axis' discriminant is 4 a / speed^2 > 0, so it does not; scikit-fmm would raise on +inf)
        ok1, r1 = _solve(0, 0.0, o1, u1, inv_s2, idx2)
        ok0, r0 = _solve(o0, u0, 0, 0.0, inv_s2, idx2)
        if not ok1:
            r1 = math.inf
        if not ok0:
            r0 = math.inf
        r = r0 if r1 > r0 else r1
    return r


# --- the priority queue: a binary min-heap of (key, cell) with each cell's position ---------------------------


@_jit
def _sift_up(hkey, hcell, pos, i):
    """Move entry ``i`` towards the root while its key is smaller than its parent's."""
    key = hkey[i]
    cell = hcell[i]
    while i > 0:
        parent = (i - 1) >> 1
        if key < hkey[parent]:
            hkey[i] = hkey[parent]
            hcell[i] = hcell[parent]
            pos[hcell[i]] = i
            i = parent
        else:
            break
    hkey[i] = key
    hcell[i] = cell
    pos[cell] = i


@_jit
def _sift_down(hkey, hcell, pos, i, n):
    """Move entry ``i`` towards the leaves while a child's key is smaller."""
    key = hkey[i]
    cell = hcell[i]
    while True:
        child = 2 * i + 1
        if child >= n:
            break
        right = child + 1
        if right < n and hkey[right] < hkey[child]:
            child = right
        if hkey[child] < key:
            hkey[i] = hkey[child]
            hcell[i] = hcell[child]
            pos[hcell[i]] = i
            i = child
        else:
            break
    hkey[i] = key
    hcell[i] = cell
    pos[cell] = i


@_jit
def _set(hkey, hcell, pos, n, cell, key):
    i = pos[cell]
    old = hkey[i]
    hkey[i] = key
    if key > old:
        _sift_down(hkey, hcell, pos, i, n)
    elif key < old:
        _sift_up(hkey, hcell, pos, i)


@_jit
def _pop(hkey, hcell, pos, n):
    """Remove the root of a heap of ``n`` entries; returns its cell (the caller reads ``hkey[0]`` before)."""
    cell = hcell[0]
    last = n - 1
    if last > 0:
        hkey[0] = hkey[last]
        hcell[0] = hcell[last]
        _sift_down(hkey, hcell, pos, 0, last)
    return cell


# --- set-up and marching ----------------------------------------------------------------------------------------


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
def start_front(W, flag, t, sgn, speed, unit, idx2, h, phi_win, k0, hkey, hcell, pos):
    """The initial front from the zero level set of ``phi`` (given on a window around the goal).

    ``phi_win`` is ``phi`` on the ``(r, c)`` window whose top-left cell has
    padded index ``k0``; outside the window ``phi > 0`` and no cell borders the
    level set.  Freezes the bordering cells, codes ``phi``'s sign of the window's
    cells in ``sgn``, and pushes every far cell next to a frozen one (raster
    order, as scikit-fmm).  Returns the heap's size, or -1 when nothing was
    frozen (scikit-fmm: "no zero level set").
    """
    r, c = phi_win.shape
    dist = np.zeros((r, c))
    frozen = np.zeros((r, c), dtype=np.bool_)
    for i in range(r):
        for j in range(c):
            k = k0 + i * W + j
            ph = phi_win[i, j]
            sgn[k] = 1 if ph < 0.0 else (2 if ph == 0.0 else 0)
    nfrozen = 0
    for i in range(r):
        for j in range(c):
            k = k0 + i * W + j
            if flag[k] == MASK:
                continue
            ph = phi_win[i, j]
            if ph == 0.0:
                frozen[i, j] = True
                dist[i, j] = 0.0
                nfrozen += 1
                continue
            l0 = 0.0
            l1 = 0.0
            borders = False
            for axis in range(2):
                for d in (-1, 1):
                    ii = i + d if axis == 0 else i
                    jj = j if axis == 0 else j + d
                    if ii < 0 or ii >= r or jj < 0 or jj >= c:
                        continue  # outside the window: phi > 0 there, and phi > 0 here (see the caller)
                    if flag[k0 + ii * W + jj] == MASK:
                        continue
                    pn = phi_win[ii, jj]
                    if ph * pn < 0.0:
                        borders = True
                        dd = h * ph / (ph - pn)
                        if axis == 0:
                            if l0 == 0.0 or l0 > dd:
                                l0 = dd
                        else:
                            if l1 == 0.0 or l1 > dd:
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
                s = 1.0 if unit else speed[k]
                t[k] = abs(dist[i, j] / s)
    # the narrow band: far cells next to a frozen one, in raster order (all lie in the window grown by one)
    n = 0
    for i in range(-1, r + 1):
        for j in range(-1, c + 1):
            k = k0 + i * W + j
            if flag[k] != FAR:
                continue
            if flag[k - W] == FROZEN or flag[k + W] == FROZEN or flag[k - 1] == FROZEN or flag[k + 1] == FROZEN:
                u = _update(k, W, flag, t, sgn, speed, unit, idx2)
                flag[k] = NARROW
                t[k] = u
                hkey[n] = abs(u)
                hcell[n] = k
                pos[k] = n
                _sift_up(hkey, hcell, pos, n)
                n += 1
    return n


@_jit
def march(W, flag, t, sgn, speed, unit, idx2, hkey, hcell, pos, state, want, batch):
    """Accept cells until every wanted cell is frozen or the front has stopped.

    ``state`` = [heap size, wanted cells not yet frozen, cells accepted so far];
    ``want[k]`` is 1 for a wanted cell (cleared when it is accepted).
    """
    n = state[0]
    remaining = state[1]
    accepted = state[2]
    while n > 0 and remaining > 0:
        value = hkey[0]
        nb = 0
        while n > 0 and hkey[0] == value:
            k = _pop(hkey, hcell, pos, n)
            n -= 1
            flag[k] = FROZEN
            batch[nb] = k
            nb += 1
            if want[k]:
                want[k] = 0
                remaining -= 1
        accepted += nb
        for b in range(nb):
            c = batch[b]
            tc = t[c]
            for s in (W, 1):
                for d in (-1, 1):
                    m = c + d * s
                    fm = flag[m]
                    if fm == NARROW:
                        # c is m's +1 side when d == -1: not an input when m's -1 side is frozen and no larger
                        if d == -1 and flag[m - s] == FROZEN and abs(t[m - s]) <= abs(tc):
                            continue
                        u = _update(m, W, flag, t, sgn, speed, unit, idx2)
                        if u != 0.0:
                            t[m] = u
                            _set(hkey, hcell, pos, n, m, abs(u))
                    elif fm == FAR:
                        u = _update(m, W, flag, t, sgn, speed, unit, idx2)
                        if u != 0.0:
                            t[m] = u
                            flag[m] = NARROW
                            hkey[n] = abs(u)
                            hcell[n] = m
                            pos[m] = n
                            _sift_up(hkey, hcell, pos, n)
                            n += 1
                    elif fm == FROZEN:
                        m2 = m + d * s
                        if flag[m2] == NARROW:
                            # c enters m2's update only as its second-order neighbour behind m, if no larger than m
                            tm = t[m]
                            if (tc <= tm and tm >= 0.0) or (tc >= tm and tm <= 0.0):
                                u = _update(m2, W, flag, t, sgn, speed, unit, idx2)
                                if u != 0.0:
                                    t[m2] = u
                                    _set(hkey, hcell, pos, n, m2, abs(u))
    state[0] = n
    state[1] = remaining
    state[2] = accepted


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
