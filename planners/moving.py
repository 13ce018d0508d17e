"""Moving obstacles of an environment: discs that follow waypoints deterministically in experiment time.

An environment's ``"moving_obstacles"`` (docs/planners.md, "Moving obstacles") is a list of::

    {"radius": 0.04, "waypoints": [[x, y], ...], "speed": 0.05,
     "repeat": "once" | "loop" | "pingpong", "delay_s": 0}

(m, m/s, s).  Obstacle time ``t`` counts from the robot's path start (its
``EV,START``): until ``delay_s`` the disc stands at its first waypoint, then
it runs along the polyline at ``speed``; ``once`` stops at the last
waypoint, ``loop`` returns to the first one and goes round again,
``pingpong`` runs back and forth.  Instead of ``waypoints`` an obstacle may
give ``"random_walk": {"seed", "start", "steps", "step_m"}``: a seeded walk
of ``steps`` legs of ``step_m`` in random directions, kept inside the field,
expanded once into waypoints (the same seed gives the same walk everywhere).

:func:`positions` is the pure, vectorised position function: arrays of
times in, centres out.  The agent's compiled collision check
(:mod:`robot_agent.engine.contact`) computes the same function per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import InvalidEnvironment
from .fields import check_keys
from .fields import number as _num

__all__ = ["MAX_MOVING_OBSTACLES", "MAX_OBSTACLE_RADIUS_M", "MAX_OBSTACLE_SPEED_M_S", "REPEAT_MODES",
           "MovingObstacle", "obstacle_at", "parse_moving_obstacles", "positions", "track_arrays"]

#: the tracked-robot budget: the overhead camera tracks the robot and at most this many emulated obstacle robots
MAX_MOVING_OBSTACLES = 16
#: fastest an obstacle may move (m/s): what an emulated robot the testbed drives can do
MAX_OBSTACLE_SPEED_M_S = 0.3
#: largest obstacle radius (m)
MAX_OBSTACLE_RADIUS_M = 0.25
MAX_WAYPOINTS = 1000
MAX_DELAY_S = 3600.0
#: repeat modes and their codes in compiled code and on the wire
REPEAT_MODES = {"once": 0, "loop": 1, "pingpong": 2}
_KEYS = {"radius", "waypoints", "random_walk", "speed", "repeat", "delay_s"}
_WALK_KEYS = {"seed", "start", "steps", "step_m"}


@dataclass(frozen=True)
class MovingObstacle:
    """A disc of ``radius`` (m) moving along ``waypoints`` (m) at ``speed`` (m/s) after ``delay_s`` (s).

    ``random_walk`` keeps the walk's specification when the waypoints were generated from it.
    """

    radius: float
    waypoints: tuple[tuple[float, float], ...]
    speed: float
    repeat: str = "once"
    delay_s: float = 0.0
    random_walk: tuple[tuple[str, Any], ...] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON form accepted by :func:`parse_moving_obstacles`."""
        out: dict[str, Any] = {"radius": self.radius, "speed": self.speed, "repeat": self.repeat,
                               "delay_s": self.delay_s}
        if self.random_walk is not None:
            walk = dict(self.random_walk)
            out["random_walk"] = {**walk, "start": list(walk["start"])}
        else:
            out["waypoints"] = [list(p) for p in self.waypoints]
        return out

    def position(self, t: np.ndarray) -> np.ndarray:
        """Centres ``(T, 2)`` (m) at obstacle times ``t`` ``(T,)`` (s)."""
        return positions((self,), t)[0]


def _track(ob: MovingObstacle) -> tuple[np.ndarray, np.ndarray]:
    """The polyline actually run (``loop`` closes it) and its cumulative arc length (m)."""
    pts = np.asarray(ob.waypoints, dtype=float).reshape(-1, 2)
    if ob.repeat == "loop" and len(pts) > 1:
        pts = np.vstack([pts, pts[:1]])
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    return pts, cum


def _distance_along(d: np.ndarray, length: float, repeat: str) -> np.ndarray:
    """Arc length reached after travelling ``d`` (m) on a track of ``length`` (m)."""
    if length <= 0.0:
        return np.zeros_like(d)
    if repeat == "loop":
        return np.mod(d, length)
    if repeat == "pingpong":
        r = np.mod(d, 2.0 * length)
        return np.where(r > length, 2.0 * length - r, r)
    return np.minimum(d, length)


def positions(obstacles: Sequence[MovingObstacle], t: np.ndarray) -> np.ndarray:
    """Centres ``(M, T, 2)`` (m) of ``obstacles`` at obstacle times ``t`` ``(T,)`` (s from the path start)."""
    tt = np.asarray(t, dtype=float).reshape(-1)
    out = np.empty((len(obstacles), len(tt), 2))
    for m, ob in enumerate(obstacles):  # a loop over the few obstacles; times are vectorised
        pts, cum = _track(ob)
        s = _distance_along(ob.speed * np.maximum(tt - ob.delay_s, 0.0), float(cum[-1]), ob.repeat)
        out[m, :, 0] = np.interp(s, cum, pts[:, 0])
        out[m, :, 1] = np.interp(s, cum, pts[:, 1])
    return out


def obstacle_at(obstacles: Sequence[MovingObstacle], point: Sequence[float], t: float,
                clearance: float) -> int | None:
    """Index of the first obstacle whose disc comes closer than ``clearance`` (m) to ``point`` (x, y; m) at
    obstacle time ``t`` (s), or None."""
    if not obstacles:
        return None
    centres = positions(obstacles, np.array([float(t)]))[:, 0]
    radii = np.array([o.radius for o in obstacles])
    near = np.hypot(centres[:, 0] - point[0], centres[:, 1] - point[1]) - radii < clearance
    return int(np.argmax(near)) if near.any() else None


def track_arrays(obstacles: Sequence[MovingObstacle]) -> tuple[np.ndarray, np.ndarray]:
    """Obstacles as numbers: ``params`` ``(M, 4)`` radius m, speed m/s, repeat code, delay s; and the
    waypoints ``(M, K, 2)`` m padded with each one's last waypoint (what ``T,T,M`` carries)."""
    params = np.array([[o.radius, o.speed, REPEAT_MODES[o.repeat], o.delay_s] for o in obstacles]).reshape(-1, 4)
    k = max((len(o.waypoints) for o in obstacles), default=1)
    pts = np.zeros((len(obstacles), k, 2))
    for m, o in enumerate(obstacles):
        w = np.asarray(o.waypoints, dtype=float)
        pts[m, : len(w)] = w
        pts[m, len(w):] = w[-1]
    return params, pts


# ---------------------------------------------------------------- parsing


def _inside(x: float, y: float, size: tuple[float, float], where: str) -> None:
    if not (0.0 <= x <= size[0] and 0.0 <= y <= size[1]):
        raise InvalidEnvironment(f"{where} ({x}, {y}) must lie inside the field 0..{size[0]} x 0..{size[1]} m")


def _point(value: Any, where: str, size: tuple[float, float]) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise InvalidEnvironment(f"{where} must be [x, y] in metres, got {value!r}")
    x, y = _num(value[0], f"{where}[0]"), _num(value[1], f"{where}[1]")
    _inside(x, y, size, where)
    return (x, y)


def _walk(spec: Any, where: str, radius: float, size: tuple[float, float]) -> tuple[tuple, tuple]:
    """The waypoints of a seeded random walk and its normalised specification."""
    if not isinstance(spec, Mapping):
        raise InvalidEnvironment(f"{where} must be an object with {', '.join(sorted(_WALK_KEYS))}")
    check_keys(spec, _WALK_KEYS, where)
    for key in sorted(_WALK_KEYS):
        if key not in spec:
            raise InvalidEnvironment(f"{where}.{key} is missing")
    seed, steps = spec["seed"], spec["steps"]
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise InvalidEnvironment(f"{where}.seed must be an integer in [0, 2**63), got {seed!r}")
    if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps < MAX_WAYPOINTS:
        raise InvalidEnvironment(f"{where}.steps must be an integer in [1, {MAX_WAYPOINTS - 1}], got {steps!r}")
    step_m = _num(spec["step_m"], f"{where}.step_m")
    if not 0 < step_m <= max(size):
        raise InvalidEnvironment(f"{where}.step_m must be in (0, {max(size)}] m, got {step_m}")
    start = _point(spec["start"], f"{where}.start", size)
    angles = np.random.default_rng([seed, 0x0B57AC1E]).uniform(-math.pi, math.pi, steps)
    lo, hi = np.array([radius, radius]), np.array(size) - radius
    pts = [np.array(start)]
    for a in angles:  # each leg is clipped to the field: the walk depends on where the last one ended
        pts.append(np.clip(pts[-1] + step_m * np.array([math.cos(a), math.sin(a)]), np.minimum(lo, hi),
                           np.maximum(lo, hi)))
    norm = (("seed", seed), ("start", start), ("steps", steps), ("step_m", step_m))
    return tuple((float(p[0]), float(p[1])) for p in pts), norm


def _obstacle(obj: Any, i: int, size: tuple[float, float]) -> MovingObstacle:
    where = f"moving_obstacles[{i}]"
    if not isinstance(obj, Mapping):
        raise InvalidEnvironment(f"{where} must be an object, got {type(obj).__name__}")
    check_keys(obj, _KEYS, where)
    for key in ("radius", "speed"):
        if key not in obj:
            raise InvalidEnvironment(f"{where}.{key} is missing")
    radius = _num(obj["radius"], f"{where}.radius")
    if not 0 < radius <= MAX_OBSTACLE_RADIUS_M:
        raise InvalidEnvironment(f"{where}.radius must be in (0, {MAX_OBSTACLE_RADIUS_M}] m, got {radius}")
    speed = _num(obj["speed"], f"{where}.speed")
    if not 0 < speed <= MAX_OBSTACLE_SPEED_M_S:
        raise InvalidEnvironment(f"{where}.speed must be in (0, {MAX_OBSTACLE_SPEED_M_S}] m/s (an emulated "
                                 f"robot's top speed), got {speed}")
    repeat = obj.get("repeat", "once")
    if not isinstance(repeat, str) or repeat not in REPEAT_MODES:  # (a dict is unhashable: refuse it too)
        raise InvalidEnvironment(f"{where}.repeat must be one of {', '.join(REPEAT_MODES)}, got {repeat!r}")
    delay = _num(obj.get("delay_s", 0.0), f"{where}.delay_s")
    if not 0 <= delay <= MAX_DELAY_S:
        raise InvalidEnvironment(f"{where}.delay_s must be in [0, {MAX_DELAY_S:g}] s, got {delay}")
    if ("waypoints" in obj) == ("random_walk" in obj):
        raise InvalidEnvironment(f"{where} needs exactly one of waypoints or random_walk")
    walk = None
    if "random_walk" in obj:
        pts, walk = _walk(obj["random_walk"], f"{where}.random_walk", radius, size)
    else:
        raw = obj["waypoints"]
        if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_WAYPOINTS:
            raise InvalidEnvironment(f"{where}.waypoints must be a list of 1 to {MAX_WAYPOINTS} [x, y] points")
        pts = tuple(_point(p, f"{where}.waypoints[{j}]", size) for j, p in enumerate(raw))
    return MovingObstacle(radius, pts, speed, repeat, delay, walk)


def parse_moving_obstacles(raw: Any, size: tuple[float, float]) -> tuple[MovingObstacle, ...]:
    """Validate an environment's ``moving_obstacles`` list in a field of ``size`` (m); errors name the field."""
    if not isinstance(raw, list):
        raise InvalidEnvironment(f"moving_obstacles must be a list, got {type(raw).__name__}")
    if len(raw) > MAX_MOVING_OBSTACLES:
        raise InvalidEnvironment(f"moving_obstacles must have at most {MAX_MOVING_OBSTACLES} entries (the "
                                 f"tracker's robot budget), got {len(raw)}")
    return tuple(_obstacle(o, i, size) for i, o in enumerate(raw))
