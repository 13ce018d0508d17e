"""A run's plain data, light enough for the server's event loop: numpy and the planners, no compiled code.

What the gripper takes of an environment (blocks and moving obstacles as the wire carries them), an
explicit path's headings, where the gripper places a robot, how long a run should take, and the
replanning and collision counts a run's metrics add.  The jobs of :mod:`.jobs` build on these; the
server calls them directly.  Units: metres, radians, seconds.
"""

from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

from planners import parse_environment
from planners.metrics import direct_comparison
from planners.moving import REPEAT_MODES, positions
from planners.postprocess import headings

__all__ = ["TooFewPoses", "block_tuples", "collision_counts", "compare_runs", "exact_obstacle_tracks", "expected_duration_s",
           "explicit_path", "jittered", "json_safe", "moving_tuples", "replan_metrics", "replanning"]


class TooFewPoses(Exception):
    """Fewer than two poses were logged for a run: the tracker did not deliver (the testbed's fault)."""


def explicit_path(path: list[list[float]], goal: list[float]) -> list[list[float]]:
    """Headings for a user's explicit path (points face the next one; the last takes the goal's)."""
    p = np.asarray([q[:2] for q in path], dtype=float)
    final = goal[2] if len(goal) > 2 else None
    return np.round(headings(p, final), 6).tolist()


def jittered(pose: list[float], jitter: Optional[dict[str, float]], seed: int) -> list[float]:
    """``pose`` (x, y, theta) moved by seeded Gaussian noise of std ``jitter["xy_m"]`` per axis (m) and
    ``jitter["theta_rad"]`` (rad), each clipped at 3 std; the same seed gives the same pose."""
    if not jitter:
        return list(pose)
    rng = np.random.default_rng([int(seed), 0x6A177E8])
    dx, dy, da = np.clip(rng.standard_normal(3), -3, 3) * [jitter.get("xy_m", 0.0), jitter.get("xy_m", 0.0),
                                                            jitter.get("theta_rad", 0.0)]
    x, y, a = pose
    return [float(x + dx), float(y + dy), float(math.remainder(a + da, 2 * math.pi))]


def expected_duration_s(path_length_m: float, n_blocks: int, *, speed_m_s: float = 0.2,
                        seconds_per_block: float = 4.0) -> float:
    """Rough experiment seconds a run takes (gripper + driving), for estimates and timeouts."""
    return n_blocks * seconds_per_block + 5.0 + path_length_m / speed_m_s * 1.5


def block_tuples(env_data: dict[str, Any]) -> list[tuple[float, float, float, float, float]]:
    """The environment's blocks as the gripper's ``T,T,B`` takes them: (cx, cy, w, h, angle) in m, rad."""
    return [(b["x"], b["y"], b["w"], b["h"], b.get("angle", 0.0)) for b in env_data.get("blocks", [])]


def moving_tuples(env_data: dict[str, Any]) -> list[tuple[list[float], list[list[float]]]]:
    """The environment's moving obstacles as ``T,T,M`` takes them: per obstacle (radius m, speed m/s, repeat
    code, delay s) and its waypoints (m; a random walk expanded with its seed)."""
    if not env_data.get("moving_obstacles"):
        return []

    env = parse_environment(env_data)
    return [([o.radius, o.speed, float(REPEAT_MODES[o.repeat]), o.delay_s], [list(p) for p in o.waypoints])
            for o in env.moving_obstacles]


def replanning(controller_params: Optional[dict[str, float]]) -> bool:
    """Whether a job's controller replans (``replan`` = 1, docs/controllers.md)."""
    return bool(controller_params) and controller_params.get("replan") == 1


def replan_metrics(replans: list[tuple[int, float]]) -> dict[str, Any]:
    """A replanning run's metrics (docs/metrics.md) from its ``REPLAN`` events, each (points of the new path,
    0 when none was found; planning time s): ``replans`` (new paths followed), ``replan_failures`` and
    ``replan_time_s`` (planning time of them all, s)."""
    return {"replans": sum(1 for n, _ in replans if n > 0), "replan_failures": sum(1 for n, _ in replans if n == 0),
            "replan_time_s": float(sum(s for _, s in replans))}


def collision_counts(collided: bool, obstacle: Optional[int]) -> dict[str, int]:
    """A run's collisions by kind (docs/metrics.md): ``collisions_obstacle`` (a moving obstacle) and
    ``collisions_block`` (a block, the wall or another robot); a collision ends a run, so each is 0 or 1."""
    hit_obstacle = collided and obstacle is not None
    return {"collisions_obstacle": int(hit_obstacle), "collisions_block": int(collided and not hit_obstacle)}


def exact_obstacle_tracks(env_data: dict[str, Any], t_from: float, t_to: float, t_zero: float,
                          step_s: float = 0.05) -> list[np.ndarray]:
    """The environment's moving obstacles on their exact tracks (docs/planners.md, "Moving obstacles") from
    ``t_from`` to ``t_to`` (s, the run's clock; both included) every ``step_s`` (s), obstacle time 0 at
    ``t_zero`` (s): per moving obstacle ``(T, 4)`` t s, x m, y m, theta rad (the direction it moves in, the
    last one while it stands; its first way's before it sets off)."""
    if not env_data.get("moving_obstacles"):
        return []

    obstacles = parse_environment(env_data).moving_obstacles
    t = np.arange(t_from, t_to, step_s) if t_to > t_from else np.zeros(0)
    t = np.append(t, t_to)
    xy = positions(obstacles, t - t_zero)  # (M, T, 2)
    step = np.diff(np.concatenate([xy, xy[:, -1:]], axis=1), axis=1)  # to the next sample; none after the last
    moving = np.hypot(step[..., 0], step[..., 1]) > 1e-12
    # where it stands, the heading of the last step it moved (of the first one before it ever moved)
    last = np.maximum.accumulate(np.where(moving, np.arange(len(t)), -1), axis=1)
    idx = np.where(last >= 0, last, np.argmax(moving, axis=1)[:, None])
    theta = np.take_along_axis(np.arctan2(step[..., 1], step[..., 0]), idx, axis=1)
    return [np.column_stack([t, xy[m], theta[m]]) for m in range(len(obstacles))]


def compare_runs(sim_poses: list[list[float]], twb_poses: list[list[float]]) -> dict[str, Any]:
    """The paper's direct sim-vs-twb comparison ("ST") of two performed paths."""
    a = np.asarray(sim_poses, dtype=float).reshape(-1, 4)[:, 1:3]
    b = np.asarray(twb_poses, dtype=float).reshape(-1, 4)[:, 1:3]
    return json_safe(direct_comparison(a, b))


def json_safe(d: Any) -> Any:
    """JSON-safe: NaN/inf become None, numpy scalars become Python numbers."""
    if isinstance(d, dict):
        return {k: json_safe(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [json_safe(v) for v in d]
    if isinstance(d, (np.floating, float)):
        return float(d) if math.isfinite(d) else None
    if isinstance(d, np.integer):
        return int(d)
    if isinstance(d, np.bool_):
        return bool(d)
    return d
