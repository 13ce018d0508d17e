"""Path metrics (docs/design.md, "Metrics"): compare a planned path P0 with the path Pr a robot performed.

Pure numpy/scipy, no I/O.  Paths are ``(N, 2)`` or ``(N, 3)`` float arrays of
``x, y[, theta]`` in metres (and radians); the heading column is ignored,
every metric uses the geometry of the polyline through the points.  Times are
seconds.  See ``docs/metrics.md`` for every formula and convention.

Building blocks (arrays in, arrays out):

- :func:`resample` — ``n`` points evenly spaced by arc length, both ends kept;
- :func:`path_length` — l(P), no resampling;
- :func:`point_to_polyline_distance` — exact distance of points to a polyline;
- :func:`deviation` — P0 resampled to ``n`` points, each one's distance to Pr;
- :func:`turning_angles`, :func:`smoothness` (κ'), :func:`angle_over_length`,
  :func:`max_curvature`;
- :func:`clearance` (per resampled point), :func:`min_clearance` (exact);
- :func:`execution_time`, :func:`average_speed`, :func:`goal_reached`,
  :func:`collided`;
- :func:`hausdorff_distance`, :func:`discrete_frechet`, :func:`frechet_distance`.

JSON-ready dictionaries with the contract's key names (docs/design.md, "Metrics"):

- :func:`path_metrics` — one path (planned or performed: the same keys);
- :func:`comparison_metrics` — deviation, Hausdorff and Fréchet between two
  paths; :func:`direct_comparison` is the paper's sim-vs-field "ST";
- :func:`ratio_metrics` — performed / planned ratios;
- :func:`run_metrics` — everything for one run;
- :class:`MetricSettings` — the resampling, robot radius and goal tolerance used.

>>> import numpy as np
>>> square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
>>> path_length(square)
4.0
>>> round(smoothness(square, segments=4), 6)  # three right angles: sqrt(3 (pi/2)^2 / 3)
1.570796
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree

from .environment import Environment
from .geometry import distance_to_obstacles, polyline_min_clearance
from .moving import positions

__all__ = [
    "COMPARISON_KEYS",
    "DEFAULT_GOAL_TOLERANCE",
    "DEFAULT_SAMPLES",
    "DEFAULT_SEGMENT_LENGTH",
    "DEFAULT_OBSTACLE_SAFETY",
    "MetricSettings",
    "OBSTACLE_KEYS",
    "PATH_KEYS",
    "RATIO_KEYS",
    "angle_over_length",
    "average_speed",
    "clearance",
    "collided",
    "comparison_metrics",
    "deviation",
    "direct_comparison",
    "discrete_frechet",
    "execution_time",
    "frechet_distance",
    "goal_reached",
    "hausdorff_distance",
    "max_curvature",
    "min_clearance",
    "obstacle_gaps",
    "obstacle_metrics",
    "path_length",
    "path_metrics",
    "point_to_polyline_distance",
    "ratio_metrics",
    "resample",
    "run_metrics",
    "smoothness",
    "smoothness_polyline",
    "turning_angles",
]

#: Points P0 is resampled to for deviation, clearance, Hausdorff and Fréchet
#: (docs/metrics.md, "The contract's metrics").
DEFAULT_SAMPLES = 200
#: Segment length (m) of the smoothness resampling when no segment count is given
#: (docs/metrics.md, "Smoothness κ′").
DEFAULT_SEGMENT_LENGTH = 0.05
#: Largest distance (m) between the performed path's last point and the goal that counts as arrived.
DEFAULT_GOAL_TOLERANCE = 0.05
#: Safety radius (m) of ``obstacle_time_within_s``: time the robot's gap to a moving obstacle is below it.
DEFAULT_OBSTACLE_SAFETY = 0.1
#: Segments shorter than this (m) count as zero-length and are dropped before turning angles.
ZERO_LENGTH = 1e-12

# (points x neighbours) handled at once in the exact distance passes
_CHUNK = 1 << 16
# pieces of the point-to-polyline search are at most this times the mean segment length
_CAP_FACTOR = 2.0

#: Keys of :func:`path_metrics`, in output order.
PATH_KEYS = (
    "length_m",
    "smoothness_rad",
    "aol_rad_per_m",
    "max_curvature_rad_per_m",
    "clearance_min_m",
    "clearance_mean_m",
    "collided",
    "execution_time_s",
    "average_speed_m_s",
    "goal_reached",
)
#: Keys of :func:`obstacle_metrics` (in :func:`run_metrics` when the environment has moving obstacles).
OBSTACLE_KEYS = ("obstacle_distance_min_m", "obstacle_time_within_s")
#: Keys of :func:`comparison_metrics`.
COMPARISON_KEYS = ("deviation_mean_m", "deviation_max_m", "hausdorff_m", "frechet_m")
#: Keys of :func:`ratio_metrics`, and the path metric each one divides.
RATIO_KEYS = {"length_ratio": "length_m", "smoothness_ratio": "smoothness_rad", "clearance_ratio": "clearance_min_m"}


# ---------------------------------------------------------------- validation


def _path_iv(path: Any, name: str, min_points: int = 2) -> np.ndarray:
    """``path`` as a float ``(N, 2)`` array of x, y; ``ValueError`` naming ``name`` otherwise."""
    try:
        p = np.asarray(path, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be an array of numbers with shape (N, 2) or (N, 3)") from None
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"`{name}` must have shape (N, 2) or (N, 3), got {p.shape}")
    if len(p) < min_points:
        raise ValueError(f"`{name}` must have at least {min_points} point{'s' * (min_points != 1)}, got {len(p)}")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise ValueError(f"`{name}` must be finite: point {int(np.argmax(bad))} is {p[bad][0].tolist()}")
    return p[:, :2]


def _count_iv(value: Any, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"`{name}` must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _positive_iv(value: Any, name: str, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"`{name}` must be a finite number {'>=' if allow_zero else '>'} 0, got {value!r}")
    return v


def _times_iv(t: Any, n_points: int | None = None) -> np.ndarray:
    try:
        ts = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("`t` must be an array of numbers (s)") from None
    if ts.ndim != 1 or len(ts) < 2:
        raise ValueError(f"`t` must be a 1-D array of at least 2 times (s), got shape {ts.shape}")
    if n_points is not None and len(ts) != n_points:
        raise ValueError(f"`t` must have one time per point: {len(ts)} times for {n_points} points")
    if not np.isfinite(ts).all():
        raise ValueError(f"`t` must be finite: time {int(np.argmax(~np.isfinite(ts)))} is not")
    back = np.flatnonzero(np.diff(ts) < 0)
    if len(back):
        raise ValueError(f"`t` must be non-decreasing: time {back[0] + 1} ({ts[back[0] + 1]}) < {ts[back[0]]}")
    return ts


# ---------------------------------------------------------------- resampling and length


def _segment_lengths(p: np.ndarray) -> np.ndarray:
    d = np.diff(p, axis=0)
    return np.hypot(d[:, 0], d[:, 1])


def path_length(path: np.ndarray) -> float:
    """Length l(P) (m): the sum of the distances between consecutive points (no resampling).

    Parameters
    ----------
    path : (N, 2) or (N, 3) float array, m
        At least 2 finite points.
    """
    return float(_segment_lengths(_path_iv(path, "path")).sum())


def resample(path: np.ndarray, n: int) -> np.ndarray:
    """``n`` points evenly spaced by arc length along ``path``, both ends included.

    Parameters
    ----------
    path : (N, 2) or (N, 3) float array, m
        A polyline of at least 2 finite points.
    n : int
        Number of points wanted, >= 2.

    Returns
    -------
    (n, 2) float array, m
        ``out[0] == path[0]`` and ``out[-1] == path[-1]`` exactly; point ``k``
        lies at arc length ``k * l(P) / (n - 1)``.  A path of zero length
        gives ``n`` copies of its first point.
    """
    p = _path_iv(path, "path")
    n = _count_iv(n, "n", 2)
    return _resample(p, n)


def _resample(p: np.ndarray, n: int) -> np.ndarray:
    lengths = _segment_lengths(p)
    s = np.concatenate([[0.0], np.cumsum(lengths)])
    total = s[-1]
    if total <= 0:
        return np.repeat(p[:1], n, axis=0)
    target = np.linspace(0.0, total, n)
    # the segment each target falls on; zero-length segments are never chosen
    i = np.clip(np.searchsorted(s, target, side="right") - 1, 0, len(lengths) - 1)
    seg_len = lengths[i]
    frac = np.divide(target - s[i], seg_len, out=np.zeros(n), where=seg_len > 0)
    out = p[i] + (p[i + 1] - p[i]) * np.clip(frac, 0.0, 1.0)[:, None]
    out[0], out[-1] = p[0], p[-1]
    return out


# ---------------------------------------------------------------- distances between paths


def point_to_polyline_distance(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Exact distance (m) from each point to the polyline (nearest point on any of its segments).

    Parameters
    ----------
    points : (N, 2) or (N, 3) float array, m
    polyline : (M, 2) or (M, 3) float array, m
        At least 1 point (a single point is a degenerate polyline).

    Returns
    -------
    (N,) float array, m

    Notes
    -----
    Exact point-to-segment distances, with a k-d tree only to skip segments
    that cannot be nearest.  Segments longer than twice the mean segment
    length are cut into pieces no longer than that (the union, hence the
    distance, is unchanged), so every piece has half-length at most ``H``.
    For each point the ``k`` pieces with the nearest midpoints are measured
    exactly; any other piece is at least ``d_k - H`` away (``d_k``: the k-th
    midpoint distance), so the answer is final once ``d_k - H >= best``.
    Points not yet final are queried again with ``4 k`` neighbours.  ``k``
    starts at 8, or, for more than 8192 points, at the cheapest start
    estimated on an evenly strided 1/64 pilot: a polyline much denser than
    the distances measured needs more neighbours (about
    ``2 sqrt(2 d H) / spacing``).  O((N k + M) log M) overall.
    """
    q = _path_iv(points, "points", min_points=0)
    line = _path_iv(polyline, "polyline", min_points=1)
    if len(q) == 0:
        return np.zeros(0)
    if len(line) == 1:
        return np.hypot(*(q - line[0]).T)
    a, d = line[:-1], np.diff(line, axis=0)
    lengths = np.hypot(d[:, 0], d[:, 1])
    cap = _CAP_FACTOR * lengths.mean()
    if cap > 0 and lengths.max() > cap:
        pieces = np.maximum(np.ceil(lengths / cap).astype(np.intp), 1)
        owner = np.repeat(np.arange(len(a)), pieces)
        k = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
        d = d[owner] / pieces[owner, None]
        a = a[owner] + d * k[:, None]
        lengths = lengths[owner] / pieces[owner]
    half = 0.5 * lengths.max()
    inv_len2 = np.divide(1.0, lengths * lengths, out=np.zeros_like(lengths), where=lengths > 0)
    # one row per piece (a, d, 1/|d|^2): a single gather per neighbour
    table = np.column_stack([a, d, inv_len2])
    tree = cKDTree(a + 0.5 * d)
    k = _first_k(q, tree, table, half)
    out = np.empty(len(q))
    todo = np.arange(len(q))
    while len(todo):
        best, done = _nearest_pieces(q[todo], tree, table, half, k)
        out[todo[done]] = best[done]
        todo = todo[~done]
        k = min(4 * k, len(a))
    return out


def _first_k(q: np.ndarray, tree: cKDTree, table: np.ndarray, half: float) -> int:
    """Neighbours to ask for first: 8, or for many points the cheapest start on an evenly strided 1/64 pilot.

    A polyline much denser than the distances measured needs more neighbours
    than 8; the expected cost of starting at ``k`` is the neighbours asked
    for over the passes ``k, 4k, ...`` weighted by the pilot's unsettled share.
    """
    ladder = [min(8, len(table))]
    if len(q) <= 8192:
        return ladder[0]
    pilot = q[::64]
    settled = [_nearest_pieces(pilot, tree, table, half, ladder[0])[1].mean()]
    while settled[-1] < 1.0 and ladder[-1] < len(table):
        ladder.append(min(4 * ladder[-1], len(table)))
        settled.append(_nearest_pieces(pilot, tree, table, half, ladder[-1])[1].mean())
    cost = [ladder[i] + sum(ladder[j] * (1 - settled[j - 1]) for j in range(i + 1, len(ladder))) for i in range(len(ladder))]
    return ladder[int(np.argmin(cost))]


def _nearest_pieces(
    q: np.ndarray, tree: cKDTree, table: np.ndarray, half: float, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """Smallest exact distance to the ``k`` pieces with the nearest midpoints, and whether it is final."""
    best, done = np.empty(len(q)), np.ones(len(q), dtype=bool)
    step = max(1, _CHUNK // k)  # bounded temporaries stay in cache
    for lo in range(0, len(q), step):
        part = q[lo : lo + step]
        dist, idx = tree.query(part, k=k)
        dist, idx = dist.reshape(len(part), k), idx.reshape(len(part), k)
        b = best[lo : lo + step] = _point_segment_distance(part, table[idx]).min(axis=1)
        if k < len(table):
            done[lo : lo + step] = dist[:, -1] - half >= b
    return best, done


def _point_segment_distance(q: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Distances ``(N, K)`` from points ``q`` ``(N, 2)`` to segments ``seg`` ``(N, K, 5)``: rows (a, d, 1/|d|²).

    The segment runs from ``a`` to ``a + d``; ``1/|d|²`` is 0 for a zero-length one.
    """
    rx, ry = q[:, None, 0] - seg[..., 0], q[:, None, 1] - seg[..., 1]
    dx, dy = seg[..., 2], seg[..., 3]
    t = np.clip((rx * dx + ry * dy) * seg[..., 4], 0.0, 1.0)
    return np.hypot(rx - t * dx, ry - t * dy)


def deviation(planned: np.ndarray, performed: np.ndarray, n: int = DEFAULT_SAMPLES) -> np.ndarray:
    """Deviation profile (m): P0 resampled to ``n`` points, each one's exact distance to the polyline Pr.

    Parameters
    ----------
    planned, performed : (N, 2) or (N, 3) float arrays, m
        P0 and Pr, at least 2 points each.
    n : int
        Samples of P0 (default 200; docs/metrics.md, "The contract's metrics").

    Returns
    -------
    (n,) float array, m
        Its mean and max are ``deviation_mean_m`` and ``deviation_max_m``.
    """
    p0 = _path_iv(planned, "planned")
    pr = _path_iv(performed, "performed")
    return point_to_polyline_distance(_resample(p0, _count_iv(n, "n", 2)), pr)


def hausdorff_distance(a: np.ndarray, b: np.ndarray, n: int = DEFAULT_SAMPLES) -> float:
    """Symmetric Hausdorff distance (m) between two polylines, from ``n`` arc-length samples of each.

    ``max(max_i d(a_i, B), max_j d(b_j, A))`` with ``a_i``/``b_j`` the ``n``
    resampled points and exact point-to-polyline distances, so the result is
    at least the deviation max and at most ``spacing / 2`` below the exact
    continuous Hausdorff distance (the distance to a polyline is 1-Lipschitz).
    """
    pa, pb = _path_iv(a, "a"), _path_iv(b, "b")
    n = _count_iv(n, "n", 2)
    return float(
        max(point_to_polyline_distance(_resample(pa, n), pb).max(), point_to_polyline_distance(_resample(pb, n), pa).max())
    )


def discrete_frechet(a: np.ndarray, b: np.ndarray) -> float:
    """Discrete Fréchet distance (m) between two point sequences (Eiter & Mannila's coupling distance).

    The dynamic programme ``c[i, j] = max(|a_i - b_j|, min(c[i-1, j],
    c[i-1, j-1], c[i, j-1]))`` is swept one anti-diagonal ``i + j = k`` at a
    time, each diagonal as one vectorised step: O(N M) work, O(N + M) memory.

    Parameters
    ----------
    a : (N, 2) or (N, 3) float array, m
    b : (M, 2) or (M, 3) float array, m
        At least 1 point each.
    """
    pa, pb = _path_iv(a, "a", min_points=1), _path_iv(b, "b", min_points=1)
    n, m = len(pa), len(pb)
    ax, ay = pa[:, 0], pa[:, 1]
    bx, by = pb[::-1, 0].copy(), pb[::-1, 1].copy()  # b reversed: diagonal cells are contiguous in both
    # slot i + 1 holds cell (i, k - i) of a diagonal; slot 0 stays +inf (i = -1)
    prev2 = np.full(n + 1, np.inf)
    prev1 = np.full(n + 1, np.inf)
    prev1[1] = math.hypot(ax[0] - bx[m - 1], ay[0] - by[m - 1])
    for k in range(1, n + m - 1):
        lo, hi = max(0, k - m + 1), min(k, n - 1) + 1
        r = m - 1 - k  # index in reversed b of j = k - i, minus i
        dist = np.hypot(ax[lo:hi] - bx[r + lo : r + hi], ay[lo:hi] - by[r + lo : r + hi])
        cur = np.full(n + 1, np.inf)
        np.maximum(dist, np.minimum(np.minimum(prev1[lo:hi], prev1[lo + 1 : hi + 1]), prev2[lo:hi]), out=cur[lo + 1 : hi + 1])
        prev2, prev1 = prev1, cur
    return float(prev1[n])


def frechet_distance(a: np.ndarray, b: np.ndarray, n: int = DEFAULT_SAMPLES) -> float:
    """Discrete Fréchet distance (m) between two polylines, each resampled to ``n`` points by arc length.

    Resampling first makes the value independent of how densely each path
    was logged; it is within ``(spacing_a + spacing_b) / 2`` of the
    continuous Fréchet distance of the resampled polylines.  O(n²) time.
    """
    n = _count_iv(n, "n", 2)
    return discrete_frechet(_resample(_path_iv(a, "a"), n), _resample(_path_iv(b, "b"), n))


# ---------------------------------------------------------------- turning


def turning_angles(path: np.ndarray) -> np.ndarray:
    """Turning angle (rad, in [0, π]) at every interior vertex, zero-length segments dropped first.

    ``α = atan2(|u × v|, u · v)`` for consecutive segment vectors ``u``,
    ``v``: the same angle as ``arccos(clip(u·v / (|u||v|), -1, 1))`` but
    accurate near 0 and π, never NaN; wrapping is implicit (a heading change
    from 170° to -170° is 20°), a reversal is π.

    Returns
    -------
    (k - 1,) float array, rad
        ``k`` = number of segments of length > 1e-12 m (empty if k < 2).
    """
    return _turning(_path_iv(path, "path"))[0]


def _turning(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Turning angles and the lengths of the non-zero segments they join."""
    d = np.diff(p, axis=0)
    lengths = np.hypot(d[:, 0], d[:, 1])
    keep = lengths > ZERO_LENGTH
    d, lengths = d[keep], lengths[keep]
    u, v = d[:-1], d[1:]
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    dot = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]
    return np.arctan2(np.abs(cross), dot), lengths


def smoothness_polyline(
    path: np.ndarray, segments: int | None = None, segment_length: float = DEFAULT_SEGMENT_LENGTH
) -> np.ndarray:
    """The polyline κ', AOL and curvature are measured on: ``path`` resampled into ``m`` segments.

    ``m = segments`` when given, else ``max(2, ceil(l(P) / segment_length))``
    (segments of at most ``segment_length`` metres, default 0.05 m;
    docs/metrics.md, "Smoothness κ′").

    Returns
    -------
    (m + 1, 2) float array, m
    """
    p = _path_iv(path, "path")
    return _smoothness_polyline(p, segments, segment_length)


def _smoothness_polyline(p: np.ndarray, segments: int | None, segment_length: float) -> np.ndarray:
    if segments is None:
        step = _positive_iv(segment_length, "segment_length")
        total = float(_segment_lengths(p).sum())
        m = max(2, math.ceil(total / step * (1 - 1e-12)))
    else:
        m = _count_iv(segments, "segments", 2)
    return _resample(p, m + 1)


def _shape(p: np.ndarray, segments: int | None, segment_length: float) -> tuple[float, float, float]:
    """κ' (rad), AOL (rad/m) and maximum curvature (rad/m) of ``p`` on its smoothness resampling."""
    alpha, lengths = _turning(_smoothness_polyline(p, segments, segment_length))
    if not len(alpha):
        return 0.0, 0.0, 0.0
    return (
        float(np.sqrt(np.mean(alpha * alpha))),
        float(alpha.sum() / lengths.sum()),
        float(np.max(alpha / (0.5 * (lengths[:-1] + lengths[1:])))),
    )


def smoothness(path: np.ndarray, segments: int | None = None, segment_length: float = DEFAULT_SEGMENT_LENGTH) -> float:
    """Smoothness κ' (rad): the RMS turning angle of ``path`` resampled into ``m`` segments.

    ``κ' = sqrt(Σ_{i=2..m} α_i² / (m - 1))`` with α_i the turning angle
    between segments ``i - 1`` and ``i`` (:func:`turning_angles`), after
    dropping zero-length segments (``m`` then counts the remaining ones).
    0 for a straight path, and for a path with fewer than 2 non-zero segments
    (docs/metrics.md, "Smoothness κ′").

    Parameters
    ----------
    path : (N, 2) or (N, 3) float array, m
    segments : int, optional
        ``m``, >= 2; default: segments of ``segment_length``.
    segment_length : float, m
        Default 0.05 m.
    """
    return _shape(_path_iv(path, "path"), segments, segment_length)[0]


def angle_over_length(
    path: np.ndarray, segments: int | None = None, segment_length: float = DEFAULT_SEGMENT_LENGTH
) -> float:
    """Angle over length, AOL (rad/m): ``Σ α_i / Σ ℓ_i`` on the smoothness resampling (Bench-MR's AOL).

    Total turning divided by the length of the same resampled polyline; 0
    when there is no vertex (straight or zero-length path).
    """
    return _shape(_path_iv(path, "path"), segments, segment_length)[1]


def max_curvature(path: np.ndarray, segments: int | None = None, segment_length: float = DEFAULT_SEGMENT_LENGTH) -> float:
    """Largest discrete curvature (rad/m) on the smoothness resampling: ``max α_i / ((ℓ_{i-1} + ℓ_i) / 2)``.

    A polyline's curvature is concentrated at its vertices; spreading each
    turning angle over the mean length of the two segments it joins gives a
    finite value that depends on the resampling (a sharp 90° corner with
    0.05 m segments reads π/2 / 0.05 ≈ 31 rad/m).  0 if there is no vertex.
    """
    return _shape(_path_iv(path, "path"), segments, segment_length)[2]


# ---------------------------------------------------------------- clearance and flags


def clearance(env: Environment, path: np.ndarray, n: int = DEFAULT_SAMPLES) -> np.ndarray:
    """Clearance profile (m): ``path`` resampled to ``n`` points, each one's exact obstacle distance.

    Obstacles are the blocks and the field boundary; a point inside a block
    or outside the field has clearance 0.  The mean is ``clearance_mean_m``.
    """
    return distance_to_obstacles(env, _resample(_path_iv(path, "path"), _count_iv(n, "n", 2)))


def min_clearance(env: Environment, path: np.ndarray) -> float:
    """Exact minimum clearance (m) over every point of the polyline, not only sampled ones.

    The minimum over all segments of their exact distance to blocks and walls
    (:func:`planners.geometry.polyline_clearance`): a straight segment
    passing a block's corner gets the analytic distance even when no vertex
    or sample is near it.  Always <= the minimum of :func:`clearance`.
    """
    return polyline_min_clearance(env, _path_iv(path, "path"))


def collided(env: Environment, path: np.ndarray, robot_radius: float = 0.0) -> bool:
    """Whether a disc of ``robot_radius`` (m) centred on the path touches an obstacle.

    True when the exact minimum clearance is below ``robot_radius`` (or 0,
    i.e. the centre touches an obstacle, when ``robot_radius`` is 0).
    """
    return _collided(min_clearance(env, path), robot_radius)


def _collided(min_clear: float, robot_radius: float) -> bool:
    r = _positive_iv(robot_radius, "robot_radius", allow_zero=True)
    return bool(min_clear < r or min_clear <= 0.0)


def goal_reached(path: np.ndarray, goal: np.ndarray, tolerance: float = DEFAULT_GOAL_TOLERANCE) -> bool:
    """Whether the path's last point is within ``tolerance`` (m) of ``goal`` (x, y; a heading is ignored)."""
    p = _path_iv(path, "path")
    g = np.asarray(goal, dtype=float).ravel()
    if g.size not in (2, 3) or not np.isfinite(g).all():
        raise ValueError(f"`goal` must be finite x, y[, theta], got {g.tolist()}")
    tol = _positive_iv(tolerance, "tolerance", allow_zero=True)
    return bool(math.hypot(p[-1, 0] - g[0], p[-1, 1] - g[1]) <= tol)


def execution_time(t: np.ndarray, start: float | None = None, done: float | None = None) -> float:
    """Execution time (s): ``done - start`` (the times of ``EV,START`` and ``EV,DONE``) when given.

    Otherwise (offline) the last logged time minus the first, ``t[-1] - t[0]``
    of the non-decreasing times ``t``.
    """
    if start is not None or done is not None:
        if start is None or done is None:
            raise ValueError("give both `start` and `done` (s), or neither")
        s, e = float(start), float(done)
        if not (math.isfinite(s) and math.isfinite(e)) or e < s:
            raise ValueError(f"`done` ({done}) must be a finite time >= `start` ({start})")
        return e - s
    ts = _times_iv(t)
    return float(ts[-1] - ts[0])


def average_speed(path: np.ndarray, duration: float) -> float:
    """Average speed (m/s): l(P) / ``duration`` — path length, not displacement; NaN if ``duration`` is 0."""
    d = _positive_iv(duration, "duration", allow_zero=True)
    length = path_length(path)
    return length / d if d > 0 else math.nan


# ---------------------------------------------------------------- dictionaries


@dataclass(frozen=True)
class MetricSettings:
    """How paths are measured; stored with the metrics so a run can be re-measured identically.

    Attributes
    ----------
    samples : int
        ``n`` of the deviation, clearance-mean, Hausdorff and Fréchet
        resampling (default 200; docs/metrics.md, "The contract's metrics").
    segments : int or None
        ``m`` of the smoothness resampling; None: segments of
        ``segment_length``.
    segment_length : float, m
        Default 0.05 m.
    robot_radius : float, m
        ``collided`` is True when the exact minimum clearance is below it
        (default 0: the centre path touches an obstacle).
    goal_tolerance : float, m
        ``goal_reached`` is True when the last point is at most this far
        from the goal (default 0.05 m).
    obstacle_safety : float, m
        ``obstacle_time_within_s`` counts the time the gap to a moving
        obstacle is below this (default 0.1 m).
    """

    samples: int = DEFAULT_SAMPLES
    segments: int | None = None
    segment_length: float = DEFAULT_SEGMENT_LENGTH
    robot_radius: float = 0.0
    goal_tolerance: float = DEFAULT_GOAL_TOLERANCE
    obstacle_safety: float = DEFAULT_OBSTACLE_SAFETY

    def __post_init__(self) -> None:
        _count_iv(self.samples, "samples", 2)
        if self.segments is not None:
            _count_iv(self.segments, "segments", 2)
        _positive_iv(self.segment_length, "segment_length")
        _positive_iv(self.robot_radius, "robot_radius", allow_zero=True)
        _positive_iv(self.goal_tolerance, "goal_tolerance", allow_zero=True)
        _positive_iv(self.obstacle_safety, "obstacle_safety", allow_zero=True)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form, keys with units: ``samples``, ``segments``, ``segment_length_m``, ..."""
        return {
            "samples": self.samples,
            "segments": self.segments,
            "segment_length_m": self.segment_length,
            "robot_radius_m": self.robot_radius,
            "goal_tolerance_m": self.goal_tolerance,
            "obstacle_safety_m": self.obstacle_safety,
        }


def _finite_or_none(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def path_metrics(
    path: np.ndarray,
    *,
    env: Environment | None = None,
    t: np.ndarray | None = None,
    start_time: float | None = None,
    done_time: float | None = None,
    goal: np.ndarray | None = None,
    settings: MetricSettings = MetricSettings(),
) -> dict[str, Any]:
    """Metrics of one path (planned or performed: the same keys, :data:`PATH_KEYS`).

    Parameters
    ----------
    path : (N, 2) or (N, 3) float array, m
    env : Environment, optional
        Without it ``clearance_min_m``, ``clearance_mean_m`` and ``collided``
        are None.
    t : (N,) float array, s, optional
        Times of the points; with ``start_time``/``done_time`` (s, the
        ``EV,START``/``EV,DONE`` times) or alone, gives ``execution_time_s``
        and ``average_speed_m_s`` (None without any time).
    goal : array of x, y[, theta], optional
        Gives ``goal_reached`` (None without it).
    settings : MetricSettings
        Resampling, robot radius and goal tolerance.

    Returns
    -------
    dict
        JSON-ready: floats, bools or None (never NaN).
    """
    p = _path_iv(path, "path")
    kappa, aol, curvature = _shape(p, settings.segments, settings.segment_length)
    out: dict[str, Any] = {
        "length_m": float(_segment_lengths(p).sum()),
        "smoothness_rad": kappa,
        "aol_rad_per_m": aol,
        "max_curvature_rad_per_m": curvature,
        "clearance_min_m": None,
        "clearance_mean_m": None,
        "collided": None,
        "execution_time_s": None,
        "average_speed_m_s": None,
        "goal_reached": None,
    }
    if env is not None:
        out["clearance_min_m"] = min_clearance(env, p)
        out["clearance_mean_m"] = float(distance_to_obstacles(env, _resample(p, settings.samples)).mean())
        out["collided"] = _collided(out["clearance_min_m"], settings.robot_radius)
    if t is not None or start_time is not None or done_time is not None:
        duration = execution_time(None if t is None else _times_iv(t, len(p)), start_time, done_time)
        out["execution_time_s"] = duration
        out["average_speed_m_s"] = _finite_or_none(out["length_m"] / duration if duration > 0 else math.nan)
    if goal is not None:
        out["goal_reached"] = goal_reached(p, goal, settings.goal_tolerance)
    return out


def obstacle_gaps(env: Environment, path: np.ndarray, t: np.ndarray, robot_radius: float = 0.0,
                  tracks: Sequence[np.ndarray] | None = None, obstacle_radius: float | None = None) -> np.ndarray:
    """Per point of ``path`` ``(N, 2+)`` (m) at obstacle times ``t`` ``(N,)`` (s from the path start), the gap
    (m) between the robot's disc of ``robot_radius`` and the nearest moving obstacle's disc: centre distance
    minus both radii, negative when they overlap; ``inf`` without moving obstacles.

    ``tracks`` (optional): where the obstacles really were, one ``(T, 3+)`` array per obstacle (t s on the
    same clock as ``t``, x m, y m; e.g. the tracker's poses of the field's obstacle robots), interpolated
    at ``t``, instead of their exact tracks; ``obstacle_radius`` (m) replaces every obstacle's radius (the
    field's robots are all one size).
    """
    p = _path_iv(path, "path")
    tt = _times_iv(t, len(p))
    obs = env.moving_obstacles
    if not obs:
        return np.full(len(p), math.inf)
    if tracks is None:
        centres = positions(obs, tt)  # (M, N, 2)
    else:
        if len(tracks) != len(obs):
            raise ValueError(f"`tracks` must give one track per moving obstacle ({len(obs)}), got {len(tracks)}")
        centres = np.empty((len(obs), len(tt), 2))
        for m, tr in enumerate(tracks):  # a loop over the few obstacles; times are vectorised
            tr = np.asarray(tr, dtype=float)
            if tr.ndim != 2 or tr.shape[1] < 3 or len(tr) == 0:
                raise ValueError(f"`tracks[{m}]` must be (T >= 1, 3+) rows t, x, y of moving obstacle {m}, got shape "
                                 f"{tr.shape}")
            centres[m, :, 0] = np.interp(tt, tr[:, 0], tr[:, 1])
            centres[m, :, 1] = np.interp(tt, tr[:, 0], tr[:, 2])
    radii = np.array([o.radius if obstacle_radius is None else obstacle_radius for o in obs])[:, None]
    gaps = np.hypot(centres[..., 0] - p[:, 0], centres[..., 1] - p[:, 1]) - radii - robot_radius
    return gaps.min(axis=0)


def obstacle_metrics(env: Environment, path: np.ndarray, t: np.ndarray, *, start_time: float | None = None,
                     settings: MetricSettings = MetricSettings(), tracks: Sequence[np.ndarray] | None = None,
                     obstacle_radius: float | None = None) -> dict[str, float | None]:
    """``obstacle_distance_min_m`` and ``obstacle_time_within_s`` of a performed path ``(N, 2+)`` (m) logged at
    experiment times ``t`` ``(N,)`` (s); obstacle time counts from ``start_time`` (the ``EV,START`` time; the
    first sample's when None).

    The distance is the smallest :func:`obstacle_gaps` value (robot disc of
    ``settings.robot_radius`` to obstacle disc); the time sums the sample
    intervals ``t[j+1] - t[j]`` whose first sample's gap is below
    ``settings.obstacle_safety``.  Both None without moving obstacles.
    ``tracks`` and ``obstacle_radius``: where the obstacles really were
    (times on the obstacle clock) and their size, as :func:`obstacle_gaps`.
    """
    if not env.moving_obstacles:
        return {key: None for key in OBSTACLE_KEYS}
    tt = _times_iv(t, len(path))
    t0 = float(tt[0]) if start_time is None else float(start_time)
    gaps = obstacle_gaps(env, path, tt - t0, settings.robot_radius, tracks, obstacle_radius)
    within = gaps[:-1] < settings.obstacle_safety
    return {"obstacle_distance_min_m": float(gaps.min()),
            "obstacle_time_within_s": float(np.diff(tt)[within].sum())}


def comparison_metrics(reference: np.ndarray, other: np.ndarray, *, samples: int = DEFAULT_SAMPLES) -> dict[str, float]:
    """Deviation of ``other`` from ``reference``, and Hausdorff / discrete Fréchet distances (m).

    ``deviation_mean_m`` / ``deviation_max_m``: ``reference`` resampled to
    ``samples`` points, their exact distances to the polyline ``other``
    (:func:`deviation`).  ``hausdorff_m`` and ``frechet_m`` use ``samples``
    points of both paths.  Keys: :data:`COMPARISON_KEYS`.
    """
    ref = _path_iv(reference, "reference")
    oth = _path_iv(other, "other")
    n = _count_iv(samples, "samples", 2)
    ref_n, oth_n = _resample(ref, n), _resample(oth, n)
    dev = point_to_polyline_distance(ref_n, oth)
    back = point_to_polyline_distance(oth_n, ref)
    return {
        "deviation_mean_m": float(dev.mean()),
        "deviation_max_m": float(dev.max()),
        "hausdorff_m": float(max(dev.max(), back.max())),
        "frechet_m": discrete_frechet(ref_n, oth_n),
    }


def direct_comparison(sim: np.ndarray, twb: np.ndarray, *, samples: int = DEFAULT_SAMPLES) -> dict[str, float]:
    """The paper's direct comparison "ST": the field (``twb``) performed path against the ``sim`` one.

    Same as :func:`comparison_metrics` with the simulated path in the role of
    P0 (it is resampled; the field path is the polyline measured against).
    """
    return comparison_metrics(sim, twb, samples=samples)


def ratio_metrics(performed: Mapping[str, Any], planned: Mapping[str, Any]) -> dict[str, float | None]:
    """Performed / planned ratios of :func:`path_metrics` dictionaries (keys: :data:`RATIO_KEYS`).

    A ratio is None when either value is missing or the planned value is 0
    (e.g. ``smoothness_ratio`` of a straight planned path).
    """
    out: dict[str, float | None] = {}
    for key, metric in RATIO_KEYS.items():
        num, den = performed.get(metric), planned.get(metric)
        ok = num is not None and den is not None and den != 0
        out[key] = _finite_or_none(num / den) if ok else None
    return out


def run_metrics(
    planned: np.ndarray,
    performed: np.ndarray,
    *,
    env: Environment | None = None,
    t: np.ndarray | None = None,
    start_time: float | None = None,
    done_time: float | None = None,
    goal: np.ndarray | None = None,
    planning_time_s: float | None = None,
    settings: MetricSettings = MetricSettings(),
    obstacle_tracks: Sequence[np.ndarray] | None = None,
    obstacle_radius: float | None = None,
) -> dict[str, Any]:
    """All metrics of one run: the performed path's, the comparison with P0, the ratios, and P0's own.

    Parameters are those of :func:`path_metrics` (``t``, ``start_time`` and
    ``done_time`` belong to the performed path); ``goal`` defaults to the
    planned path's last point; ``planning_time_s`` (s) is passed through;
    ``obstacle_tracks`` and ``obstacle_radius`` say where the moving
    obstacles really were (:func:`obstacle_metrics`; on the field).

    Returns
    -------
    dict
        Flat :data:`PATH_KEYS` of Pr, :data:`COMPARISON_KEYS` (P0 against
        Pr), :data:`RATIO_KEYS`, ``planning_time_s``, and ``"planned"``: the
        :data:`PATH_KEYS` of P0; with an ``env`` that has moving obstacles
        and times ``t``, also :data:`OBSTACLE_KEYS` (:func:`obstacle_metrics`).
    """
    p0 = _path_iv(planned, "planned")
    pr = _path_iv(performed, "performed")
    goal = p0[-1] if goal is None else goal
    done = path_metrics(pr, env=env, t=t, start_time=start_time, done_time=done_time, goal=goal, settings=settings)
    plan = path_metrics(p0, env=env, goal=goal, settings=settings)
    moving = {}
    if env is not None and env.moving_obstacles and t is not None:
        moving = obstacle_metrics(env, pr, t, start_time=start_time, settings=settings, tracks=obstacle_tracks,
                                  obstacle_radius=obstacle_radius)
    return {
        **done,
        **moving,
        **comparison_metrics(p0, pr, samples=settings.samples),
        **ratio_metrics(done, plan),
        "planning_time_s": None if planning_time_s is None else _finite_or_none(float(planning_time_s)),
        "planned": plan,
    }
