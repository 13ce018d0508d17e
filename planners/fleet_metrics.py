"""Metrics of a multi-robot run (docs/metrics.md, "Several robots"): how close the robots came, what they hit, when
they all arrived.

Every robot's tracker poses ``(N_i, 4)`` (t s, x m, y m, theta rad, one
clock for the fleet) are resampled on one time grid of ``dt`` from 0 to the
last pose of any robot; before its first pose a robot stands at it, after
its last it stands where it stopped (it ended its path, or failed).  Pairwise
centre distances are computed at once over the grid ``(R, R, T)``.
docs/metrics.md describes every key.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Optional, Sequence

import numpy as np

__all__ = ["FleetSettings", "collision_kind", "fleet_metrics", "pair_distances"]


@dataclass(frozen=True)
class FleetSettings:
    """``robot_radius`` (m, the collision radius: robots touch at twice it), ``safety_radius`` (m, centre
    distance below which two robots count as too close), ``deadlock_s`` (s without progress of any robot
    still under way that counts as a deadlock), ``progress_m`` (m a robot must move within ``deadlock_s`` to
    make progress) and ``dt`` (s, the resampling step)."""

    robot_radius: float = 0.04
    safety_radius: float = 0.2
    deadlock_s: float = 5.0
    progress_m: float = 0.01
    dt: float = 0.02

    def __post_init__(self) -> None:
        for name in ("robot_radius", "safety_radius", "deadlock_s", "progress_m", "dt"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"`{name}` must be a positive number, got {v!r}")

    def to_dict(self) -> dict[str, float]:
        """The settings as plain numbers."""
        return asdict(self)


def _grid(poses: Sequence[np.ndarray], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The time grid ``(T,)`` (s) and every robot's centre on it ``(R, T, 2)`` (m)."""
    ends = [float(p[-1, 0]) for p in poses if len(p)]
    t = np.arange(0.0, (max(ends) if ends else 0.0) + dt / 2, dt)
    xy = np.zeros((len(poses), len(t), 2))
    for i, p in enumerate(poses):
        if len(p):
            xy[i, :, 0] = np.interp(t, p[:, 0], p[:, 1])
            xy[i, :, 1] = np.interp(t, p[:, 0], p[:, 2])
    return t, xy


def pair_distances(xy: np.ndarray) -> np.ndarray:
    """Centre distances ``(R, R, T)`` (m) of robots at ``xy`` ``(R, T, 2)``; ``inf`` on the diagonal."""
    d = np.hypot(xy[:, None, :, 0] - xy[None, :, :, 0], xy[:, None, :, 1] - xy[None, :, :, 1])
    d[np.arange(len(xy)), np.arange(len(xy))] = np.inf
    return d


def collision_kind(outcome: str, obstacle: Optional[int], gap_to_robot_m: float, robot_radius: float,
                   static_clearance_m: Optional[float] = None) -> Optional[str]:
    """What a robot hit: ``robot`` (another robot), ``moving`` (a moving obstacle), ``static`` (a block or the
    wall), or None (no collision).  ``gap_to_robot_m``: the centre distance to the nearest robot when it
    stopped (m); ``static_clearance_m``: its centre's distance to the nearest block or wall then (m).  With
    both, whichever was nearer to touching it (``gap - 2 r`` against ``clearance - r``): tracker poses lag
    and scatter, so neither comes out at exactly a touch; without the clearance, a robot within two
    collision radii plus 5 mm."""
    if outcome != "COLLISION":
        return None
    if obstacle is not None:
        return "moving"
    if static_clearance_m is not None:
        return "robot" if gap_to_robot_m - 2 * robot_radius <= static_clearance_m - robot_radius else "static"
    return "robot" if gap_to_robot_m <= 2 * robot_radius + 0.005 else "static"


def _longest_run(mask: np.ndarray) -> int:
    """The longest run of True in ``mask`` (samples)."""
    if not mask.any():
        return 0
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return int((edges[1::2] - edges[::2]).max())


def fleet_metrics(poses: Sequence[np.ndarray], outcomes: Sequence[str], ends: Sequence[Optional[float]],
                  obstacles: Sequence[Optional[int]] = (), settings: FleetSettings = FleetSettings(),
                  static_clearance: Sequence[Optional[float]] = ()) -> dict[str, Any]:
    """Per-robot and fleet metrics of robots' tracker ``poses`` (each ``(N_i, 4)``: t s, x m, y m, theta rad on
    the fleet's clock), their ``outcomes`` (``DONE``, a FAIL reason, ``TIMEOUT_SIM``), the times (s) their
    paths ended (None: not ended), the moving obstacle each collided with (None: none) and, optionally, each
    one's distance from its last pose to the nearest block or wall (m; tells a collision with a robot from
    one with a block, :func:`collision_kind`).

    Returns ``{"robots": [per robot], "robot_distance_min_m", "safety_time_s", "collisions_robot",
    "collisions_moving", "collisions_static", "makespan_s", "path_length_sum_m", "time_sum_s",
    "success_rate", "deadlock", "no_progress_max_s", "settings"}`` (docs/metrics.md)."""
    r = len(poses)
    if r == 0 or len(outcomes) != r or len(ends) != r:
        raise ValueError(f"one outcome and end per robot: {r} robots, {len(outcomes)} outcomes, {len(ends)} ends")
    obs = list(obstacles) if len(obstacles) else [None] * r
    clear = list(static_clearance) if len(static_clearance) else [None] * r
    dt = settings.dt
    t, xy = _grid([np.asarray(p, dtype=float).reshape(-1, 4) for p in poses], dt)
    d = pair_distances(xy)
    closest = d.min(axis=(1, 2)) if len(t) else np.full(r, np.inf)  # (R,)
    near = (d < settings.safety_radius).any(axis=1)  # (R, T)
    step = np.hypot(*np.diff(xy, axis=1).transpose(2, 0, 1)) if len(t) > 1 else np.zeros((r, 0))
    lengths = step.sum(axis=1)
    end_t = np.array([np.inf if e is None else float(e) for e in ends])
    # progress: robots still under way that moved progress_m within the last deadlock_s
    w = max(1, int(round(settings.deadlock_s / dt)))
    under_way = t[None, :] < end_t[:, None]  # (R, T)
    if len(t) > w:
        moved = np.hypot(*(xy[:, w:] - xy[:, :-w]).transpose(2, 0, 1)) >= settings.progress_m  # (R, T - w)
        stuck = under_way[:, w:].any(axis=0) & ~(moved & under_way[:, w:]).any(axis=0)
        no_progress = (_longest_run(stuck) + w) * dt if stuck.any() else 0.0
    else:
        no_progress = 0.0
    robots = []
    kinds = {"robot": 0, "moving": 0, "static": 0}
    for i in range(r):
        stop = int(np.searchsorted(t, min(end_t[i], t[-1] if len(t) else 0.0)))
        gap = float(d[i, :, min(stop, len(t) - 1)].min()) if len(t) else np.inf
        kind = collision_kind(outcomes[i], obs[i], gap, settings.robot_radius, clear[i])
        if kind:
            kinds[kind] += 1
        robots.append({"robot": i, "outcome": outcomes[i], "done": outcomes[i] == "DONE",
                       "time_s": None if ends[i] is None else float(ends[i]), "path_length_m": float(lengths[i]),
                       "robot_distance_min_m": float(closest[i]) if np.isfinite(closest[i]) else None,
                       "safety_time_s": float(near[i].sum() * dt), "collision": kind})
    done = np.array([o == "DONE" for o in outcomes])
    finite = np.isfinite(end_t)
    return {
        "robots": robots,
        "robot_distance_min_m": float(closest.min()) if np.isfinite(closest.min()) else None,
        "safety_time_s": float(near.any(axis=0).sum() * dt),
        "collisions_robot": kinds["robot"], "collisions_moving": kinds["moving"], "collisions_static": kinds["static"],
        "makespan_s": float(end_t.max()) if done.all() else None,
        "path_length_sum_m": float(lengths.sum()),
        "time_sum_s": float(end_t[finite].sum()) if done.all() else None,
        "success_rate": float(done.mean()),
        "deadlock": bool(no_progress >= settings.deadlock_s),
        "no_progress_max_s": float(no_progress),
        "settings": settings.to_dict(),
    }
