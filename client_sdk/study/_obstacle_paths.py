"""Where a run's moving obstacles were, for the figures: on the environment's exact tracks, or where the tracker saw
a field run's obstacle robots (their stored poses); and one panel's drawing of them."""

from __future__ import annotations

from typing import Any, Optional, Sequence

import numpy as np

from .._models import ObstacleTracks

__all__ = ["EXACT", "OBSTACLE_STYLE", "TRACKED", "draw_obstacles", "obstacle_paths"]

#: the legend's names of moving obstacles: where the tracker saw a field run's obstacle robots, or their exact tracks
TRACKED, EXACT = "moving obstacle (tracked)", "moving obstacle (exact track)"


def obstacle_paths(env: dict[str, Any], t: Optional[np.ndarray], tracks: Optional[Sequence[np.ndarray]] = None,
                   radii: Optional[Sequence[float]] = None) -> tuple[list[np.ndarray], list[float], str]:
    """Each moving obstacle's centres ``(K, 2)`` (m), its radius (m) and the legend's label (:data:`TRACKED`,
    :data:`EXACT`): with ``tracks`` (``(N, 4)`` t, x, y, theta per obstacle; s, m, m, rad) where the tracker saw
    them, at times ``t`` (s, their clock; None: every pose as logged), ``radii`` default the environment's;
    else on the environment's exact tracks at obstacle times ``t`` (s)."""
    if tracks is None:
        movers, centres = _obstacle_centres(env, np.asarray(t, dtype=float))
        return list(centres), [ob.radius for ob in movers], EXACT
    if radii is None:
        radii = [float(o["radius"]) for o in env.get("moving_obstacles") or []]
    paths = [np.asarray(tr, dtype=float).reshape(-1, 4)[:, 1:3] for tr in tracks] if t is None else \
        list(_tracked_centres(tracks, t))
    return paths, list(radii), TRACKED


def _tracked_centres(tracks: Sequence[np.ndarray], t: np.ndarray) -> np.ndarray:
    """Centres ``(M, T, 2)`` (m) of obstacles whose poses ``tracks[m]`` ``(N, 4)`` (t s, x m, y m, theta) were
    logged, at times ``t`` (s, the same clock): interpolated, held before the first and after the last."""
    out = np.full((len(tracks), len(t), 2), np.nan)
    for m, tr in enumerate(tracks):  # a loop over the few obstacles; times are vectorised
        tr = np.asarray(tr, dtype=float).reshape(-1, 4)
        if len(tr):
            out[m, :, 0] = np.interp(t, tr[:, 0], tr[:, 1])
            out[m, :, 1] = np.interp(t, tr[:, 0], tr[:, 2])
    return out


def _obstacle_centres(env: dict[str, Any], t: np.ndarray) -> tuple[tuple[Any, ...], np.ndarray]:
    """The environment's moving obstacles and their centres ``(M, T, 2)`` (m) at obstacle times ``t`` (s)."""
    if not env.get("moving_obstacles"):
        return (), np.zeros((0, len(t), 2))
    from planners import parse_environment
    from planners.moving import positions

    obstacles = parse_environment(env).moving_obstacles
    return obstacles, positions(obstacles, np.maximum(t, 0.0))


#: how a panel draws its moving obstacles' paths, by what they are
OBSTACLE_STYLE = {TRACKED: {"ls": "-.", "color": "0.35", "lw": 1.0},
                   EXACT: {"ls": ":", "color": "0.45", "lw": 1.2}}


def draw_obstacles(ax, env: dict[str, Any], t_end: float,  # type: ignore[no-untyped-def]
                    tracked: Optional[ObstacleTracks]) -> Optional[str]:
    """A run's moving obstacles: where the tracker saw them (``tracked``: a field run's obstacle robots) or else
    their exact tracks from obstacle time 0 to ``t_end`` (s), each path and its disc where it started; what was
    drawn (:data:`TRACKED`, :data:`EXACT`), None if the environment has none."""
    if not env.get("moving_obstacles"):
        return None
    if tracked is None:
        paths, radii, what = obstacle_paths(env, np.linspace(0.0, max(t_end, 1.0), 200))
    else:
        paths, radii, what = obstacle_paths(env, None, tracked.tracks, tracked.radii)
    labelled = False
    for path, radius in zip(paths, radii):
        if len(path):  # a tracked obstacle the tracker never saw has no path
            ax.plot(path[:, 0], path[:, 1], **OBSTACLE_STYLE[what], label=None if labelled else what)
            ax.add_patch(_disc(path[0], radius))
            labelled = True
    return what


def _disc(centre: Any, radius: float):  # type: ignore[no-untyped-def]
    from matplotlib.patches import Circle

    return Circle(tuple(centre), radius, fc="0.6", ec="k", lw=0.5, alpha=0.7)
