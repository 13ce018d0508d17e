"""The navigation task on the engine: N robots, each alone in a world of its own, stepped in one compiled call.

:class:`NavigationFleet` is what both Gymnasium environments (:mod:`robot_agent.gym.envs`) run.  It adds no
physics: the robots are the engine's (:class:`~robot_agent.engine.sim.SimCore` with the ideal or the
emulated-field backend of a robot profile from ``contract/profiles``), driven in the engine's velocity
mode (the ``T,T,V`` of the wire protocol, :meth:`SimCore.drive`), and
:meth:`SimCore.advance` steps all of them ``frame_skip`` control steps per call.  On top it keeps each
robot's episode: its map, goal and step count, and computes observations, rewards and ends in one
compiled pass (:mod:`robot_agent.gym._kernels`).

An episode of robot ``i`` is what the engine runs for one ``T,T,V`` drive: the gripper places the robot
at the start (:meth:`SimCore.place`), the first step starts velocity mode with the episode's noise key
(drawn from the episode's generator, so a seed replays the episode exactly), every step sets the body
velocities.  Units: m, rad, s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from contract.frames import field_layout
from contract.params import robot_params
from contract.robot_profile import DEFAULT_PROFILE
from robot_agent.engine.backends import make_backend
from robot_agent.engine.noise import path_key
from robot_agent.engine.sim import SimCore, State
from robot_agent.engine.world import World

from ._kernels import observe, observe_parallel, occupied_cells, window_pad
from .maps import Environments, NavMap, build_maps

__all__ = ["NavigationFleet", "TaskConfig"]

_FAILED = int(State.FAILED)


class TaskConfig:
    """The navigation task's parameters (SI units), checked once.

    ``frame_skip``: control steps (``1 / control_rate_hz`` s each, 0.02 s for the BeBot) per environment
    step; ``max_episode_steps``: environment steps before an episode is truncated; ``occupancy_cells``
    ``K`` and ``occupancy_cell_m``: the local occupancy window, ``K x K`` cells of that size centred on the
    robot and turned with it; ``goal_tolerance_m``: the goal is reached when the robot's centre is this
    close; ``min_goal_distance_m``: drawn goals are at least this far from their start;
    ``start_clearance_m``: drawn starts and goals keep this distance from blocks and walls (default: the
    collision radius plus 0.03 m); the reward's ``progress_gain`` (per m of distance to the goal gained),
    ``step_cost``, ``goal_reward`` and ``collision_cost``; ``parallel``: compute the observations on numba's
    threads (``NUMBA_NUM_THREADS``, default every core; the same numbers, faster on an idle machine with
    many robots, slower on a busy one).
    """

    def __init__(self, *, frame_skip: int = 5, max_episode_steps: int = 600, occupancy_cells: int = 16,
                 occupancy_cell_m: float = 0.05, goal_tolerance_m: float = 0.05, min_goal_distance_m: float = 0.6,
                 start_clearance_m: float | None = None, progress_gain: float = 10.0, step_cost: float = 0.01,
                 goal_reward: float = 10.0, collision_cost: float = 10.0, parallel: bool = False) -> None:
        for name, value in (("frame_skip", frame_skip), ("max_episode_steps", max_episode_steps),
                            ("occupancy_cells", occupancy_cells)):
            if not (isinstance(value, (int, np.integer)) and value >= 1):
                raise ValueError(f"`{name}` must be an integer >= 1, got {value!r}")
        for name, value in (("occupancy_cell_m", occupancy_cell_m), ("goal_tolerance_m", goal_tolerance_m)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"`{name}` must be > 0 (m), got {value!r}")
        for name, value in (("min_goal_distance_m", min_goal_distance_m), ("progress_gain", progress_gain),
                            ("step_cost", step_cost), ("goal_reward", goal_reward),
                            ("collision_cost", collision_cost)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"`{name}` must be >= 0, got {value!r}")
        if start_clearance_m is not None and not (math.isfinite(start_clearance_m) and start_clearance_m > 0):
            raise ValueError(f"`start_clearance_m` must be > 0 (m), got {start_clearance_m!r}")
        self.frame_skip, self.max_episode_steps = int(frame_skip), int(max_episode_steps)
        self.occupancy_cells, self.occupancy_cell_m = int(occupancy_cells), float(occupancy_cell_m)
        self.goal_tolerance_m, self.min_goal_distance_m = float(goal_tolerance_m), float(min_goal_distance_m)
        self.start_clearance_m = start_clearance_m
        self.progress_gain, self.step_cost = float(progress_gain), float(step_cost)
        self.goal_reward, self.collision_cost = float(goal_reward), float(collision_cost)
        self.parallel = bool(parallel)


def _pose_iv(value: Any, name: str) -> np.ndarray:
    p = np.asarray(value, dtype=float).reshape(-1)
    if len(p) == 2:
        p = np.array([p[0], p[1], 0.0])
    if len(p) != 3 or not np.isfinite(p).all():
        raise ValueError(f"`{name}` must be x, y[, theta] (m, m, rad), got {value!r}")
    return p


class NavigationFleet:
    """``n`` robots of ``profile`` on ``backend`` (``field``: the emulated field robot; ``ideal``), each in a
    world of its own with one of ``environments`` per episode (see the module docstring)."""

    def __init__(self, n: int, environments: Environments = ("room", "blocks"), *,
                 backend: str = "field", profile: str | dict = DEFAULT_PROFILE, config: TaskConfig | None = None) -> None:
        if not (isinstance(n, (int, np.integer)) and n >= 1):
            raise ValueError(f"`n` must be an integer >= 1, got {n!r}")
        self.n = int(n)
        self.config = cfg = config or TaskConfig()
        self.params = p = robot_params(profile)
        clearance = cfg.start_clearance_m if cfg.start_clearance_m is not None else p.collision_radius_m + 0.03
        self.maps: list[NavMap] = build_maps(environments, clearance_m=clearance)
        self.size = self.maps[0].size
        sizes, world_of, origin, area = field_layout(self.n, "separate", self.size)
        self.core = SimCore(p, make_backend(backend, self.n, p), World(sizes, world_of, origin, area,
                                                                       p.collision_radius_m), log_poses=False)
        self.backend = backend
        self.res = self.maps[0].resolution
        self.pad = window_pad(cfg.occupancy_cells, cfg.occupancy_cell_m, self.res)
        self.occupied = np.ascontiguousarray(np.stack([occupied_cells(m.clearance, cfg.occupancy_cell_m, self.pad)
                                                       for m in self.maps]))
        self.watchdog_s = cfg.frame_skip * self.core.dt + 1.0
        n, k = self.n, cfg.occupancy_cells
        self.goal = np.zeros((n, 3))
        self.map_of = np.full(n, -1, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        self.last_dist = np.zeros(n)
        self.pending = np.zeros(n, dtype=bool)  # placed; velocity mode starts with the next step
        self.keys = np.zeros(n, dtype=np.uint64)
        self.obs_pose = np.zeros((n, 3), dtype=np.float32)
        self.obs_goal = np.zeros((n, 3), dtype=np.float32)
        self.obs_occ = np.zeros((n, k, k), dtype=np.uint8)
        self.reward = np.zeros(n)
        self.reached = np.zeros(n, dtype=bool)
        self.failed = np.zeros(n, dtype=bool)
        self._all = np.arange(n, dtype=np.int64)

    # ------------------------------------------------------------------ episodes

    def map_index(self, name: str | int) -> int:
        """The index of a map by environment name or index."""
        if isinstance(name, (int, np.integer)) and 0 <= int(name) < len(self.maps):
            return int(name)
        for j, m in enumerate(self.maps):
            if m.env.name == name:
                return j
        raise ValueError(f"`environment` must be one of {[m.env.name for m in self.maps]}, got {name!r}")

    def reset_robots(self, rows: np.ndarray, rngs: Sequence[np.random.Generator],
                     options: Mapping[str, Any] | None = None) -> None:
        """Begin a new episode for each robot of ``rows`` with its generator (``rngs[i]`` for robot ``i``):
        the map (``options["environment"]``, else drawn when there are several), the start and goal poses
        (``options["start"]``, ``options["goal"]``: x, y[, theta]; else drawn) and the noise key (drawn)."""
        opts = dict(options or {})
        unknown = set(opts) - {"environment", "start", "goal", "reset_mask"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)} (known: environment, start, goal)")
        core, world = self.core, self.core.world
        for i in np.asarray(rows, dtype=np.int64).tolist():
            rng = rngs[i]
            if "environment" in opts:
                m = self.map_index(opts["environment"])
            else:
                m = int(rng.integers(len(self.maps))) if len(self.maps) > 1 else 0
            nav = self.maps[m]
            start, goal = nav.sample_pair(rng, self.config.min_goal_distance_m)
            if "start" in opts:
                start = _pose_iv(opts["start"], "start")
            if "goal" in opts:
                goal = _pose_iv(opts["goal"], "goal")
            self.keys[i] = np.uint64(path_key(int(rng.integers(2**63))))
            if core.moving(i):
                core.stop(i)
            if self.map_of[i] != m:
                world.load_blocks(i, nav.blocks)
                self.map_of[i] = m
            if "start" in opts:  # a drawn start is free: its cell keeps the start clearance from everything
                why = world.place_conflict(i, (float(start[0]), float(start[1]), float(start[2])), core.backend.pose)
                if why:
                    raise ValueError(f"`start` {start.tolist()} is not free: {why}")
            core.place(i, (float(start[0]), float(start[1]), float(start[2])))
            self.goal[i] = goal
            self.steps[i] = 0
            self.pending[i] = True
            self.last_dist[i] = math.hypot(goal[0] - start[0], goal[1] - start[1])
        self._observe(np.asarray(rows, dtype=np.int64))

    # ------------------------------------------------------------------ stepping

    def step(self, actions: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Drive robots ``rows`` (default: all) with body velocities ``actions`` ``(N, 2)`` (m/s, rad/s;
        clipped to the profile's top speeds) for ``frame_skip`` control steps; the other robots stand
        still.  Returns ``(terminated, truncated)`` ``(N,)``; observations, rewards and arrivals are in the
        ``obs_*``, ``reward`` and ``reached`` arrays (rows of robots not stepped are left as they were)."""
        core = self.core
        a = np.asarray(actions, dtype=float).reshape(self.n, 2)
        rows = self._all if rows is None else np.asarray(rows, dtype=np.int64)
        starting = rows[self.pending[rows]]
        if len(starting):  # velocity mode begins: the episode's noise key, as with a T,T,V
            core.drive_from_rest(starting, a, self.keys, self.watchdog_s)  # (and drive_all)
            self.pending[starting] = False
        else:
            core.drive_all(a, self.watchdog_s)
        core.advance(self.config.frame_skip)
        self.steps[rows] += 1
        self._observe(rows)
        done = self.reached | self.failed
        return done, (self.steps >= self.config.max_episode_steps) & ~done

    def _observe(self, rows: np.ndarray) -> None:
        cfg = self.config
        np.equal(self.core.state, _FAILED, out=self.failed)
        (observe_parallel if cfg.parallel else observe)(self.core.backend.belief, self.core.backend.pose, self.goal, self.map_of, self.occupied, self.res, self.pad,
                float(self.size[0]), float(self.size[1]), cfg.occupancy_cell_m, self.failed, cfg.goal_tolerance_m,
                cfg.progress_gain, cfg.step_cost, cfg.goal_reward, cfg.collision_cost, self.last_dist, rows,
                self.obs_pose, self.obs_goal, self.obs_occ, self.reward, self.reached)
