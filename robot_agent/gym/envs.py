"""Gymnasium environments of the navigation task: :class:`NavigationEnv` (one robot) and
:class:`NavigationVectorEnv` (N robots stepped in one compiled call).

Both run :class:`~robot_agent.gym.fleet.NavigationFleet` (the engine's robots; docs/gymnasium.md).

- **Observation** (a ``Dict``): ``pose`` (x, y, theta: m, m, rad, float32) — the robot's own
  localisation (on the field robot: the tracker's fixes, late and noisy, dead-reckoned in between);
  ``goal`` (x, y, theta of the goal, same frame); ``occupancy`` (``K x K`` uint8, 1 = occupied) — the
  local window centred on the robot and turned with it: ``occupancy[a, b]`` is the cell ``a`` cells
  along the robot's heading and ``b`` to its left, counted from the window's back right corner.
- **Action**: body velocities (v m/s, w rad/s), float32, bounded by the profile's top speeds.
- **Reward**: 10 x metres gained towards the goal - 0.01 per step; +10 at the goal, -10 on a collision.
- **Ends**: terminated at the goal (the robot's actual centre within ``goal_tolerance_m``) or on a
  collision; truncated after ``max_episode_steps``.

Seeds: ``reset(seed=s)`` replays an episode exactly (map, start, goal and every noise draw of the field
robot); the vector environment's robot ``i`` runs exactly what ``NavigationEnv`` does with seed ``s + i``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from contract.robot_profile import DEFAULT_PROFILE

from .fleet import NavigationFleet, TaskConfig
from .maps import Environments

__all__ = ["NavigationEnv", "NavigationVectorEnv"]


def _spaces(fleet: NavigationFleet) -> tuple[spaces.Dict, spaces.Box]:
    w, h = fleet.size
    p, k = fleet.params, fleet.config.occupancy_cells
    lo = np.array([0.0, 0.0, -math.pi], dtype=np.float32)
    hi = np.array([w, h, math.pi], dtype=np.float32)
    obs = spaces.Dict({
        "pose": spaces.Box(lo, hi, dtype=np.float32),
        "goal": spaces.Box(lo, hi, dtype=np.float32),
        "occupancy": spaces.Box(0, 1, (k, k), dtype=np.uint8),
    })
    top = np.array([p.max_speed_m_s, p.max_angular_speed_rad_s], dtype=np.float32)
    return obs, spaces.Box(-top, top, dtype=np.float32)


class NavigationEnv(gym.Env):
    """One robot's navigation task (see the module docstring); keyword arguments as
    :class:`~robot_agent.gym.fleet.TaskConfig` takes them, plus ``environments`` (names, JSON files or
    :class:`~planners.environment.Environment` objects of one size, or a world set's directory; one per
    episode, drawn), ``backend`` (``field`` or ``ideal``)
    and ``profile`` (a robot profile of ``contract/profiles``)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, environments: Environments = ("room", "blocks"), *, backend: str = "field",
                 profile: str | dict = DEFAULT_PROFILE, render_mode: str | None = None, **task: Any) -> None:
        if render_mode is not None:
            raise ValueError(f"`render_mode` must be None (no rendering), got {render_mode!r}")
        self.fleet = NavigationFleet(1, environments, backend=backend, profile=profile, config=TaskConfig(**task))
        self.observation_space, self.action_space = _spaces(self.fleet)
        self._rows = np.zeros(1, dtype=np.int64)

    def _obs(self) -> dict[str, np.ndarray]:
        f = self.fleet
        return {"pose": f.obs_pose[0].copy(), "goal": f.obs_goal[0].copy(), "occupancy": f.obs_occ[0].copy()}

    def _info(self) -> dict[str, Any]:
        f = self.fleet
        return {"environment": f.maps[int(f.map_of[0])].env.name, "distance": float(f.last_dist[0]),
                "collided": bool(f.failed[0]), "reached": bool(f.reached[0])}

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """A new episode; ``options``: ``environment`` (a name), ``start``, ``goal`` (x, y[, theta]: m, rad)."""
        super().reset(seed=seed)
        self.fleet.reset_robots(self._rows, [self.np_random], options)
        return self._obs(), self._info()

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Drive with body velocities ``action`` (v m/s, w rad/s) for ``frame_skip`` control steps."""
        terminated, truncated = self.fleet.step(np.asarray(action, dtype=float).reshape(1, 2), self._rows)
        return self._obs(), float(self.fleet.reward[0]), bool(terminated[0]), bool(truncated[0]), self._info()


class NavigationVectorEnv(VectorEnv):
    """``num_envs`` robots of the navigation task, stepped together in one compiled call per step (next-step
    autoreset: a robot whose episode ended is reset by the following ``step``, which ignores its action
    and returns its first observation with reward 0).  Keyword arguments as :class:`NavigationEnv`."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, environments: Environments = ("room", "blocks"), *,
                 backend: str = "field", profile: str | dict = DEFAULT_PROFILE, render_mode: str | None = None,
                 **task: Any) -> None:
        if render_mode is not None:
            raise ValueError(f"`render_mode` must be None (no rendering), got {render_mode!r}")
        self.fleet = NavigationFleet(num_envs, environments, backend=backend, profile=profile,
                                     config=TaskConfig(**task))
        self.num_envs = self.fleet.n
        self.single_observation_space, self.single_action_space = _spaces(self.fleet)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs: list[np.random.Generator] = []
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    def _obs(self) -> dict[str, np.ndarray]:
        f = self.fleet
        return {"pose": f.obs_pose.copy(), "goal": f.obs_goal.copy(), "occupancy": f.obs_occ.copy()}

    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """New episodes for every robot (or those of ``options["reset_mask"]``); an int ``seed`` seeds robot
        ``i`` with ``seed + i``, a list one seed per robot; other ``options`` as :meth:`NavigationEnv.reset`."""
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"`seed` must be an int or one seed per robot ({n}), got {len(seeds)}")
        if not self._rngs:
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        else:
            self._rngs = [seeding.np_random(s)[0] if s is not None else r for s, r in zip(seeds, self._rngs)]
        mask = np.ones(n, dtype=bool) if not options or "reset_mask" not in options \
            else np.asarray(options["reset_mask"], dtype=bool).reshape(n)
        rows = np.flatnonzero(mask)
        self.fleet.reset_robots(rows, self._rngs, options)
        self._autoreset[rows] = False
        return self._obs(), {}

    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray,
                                                 dict[str, Any]]:
        """All robots drive with body velocities ``actions`` ``(num_envs, 2)`` (m/s, rad/s) for ``frame_skip``
        control steps; robots whose episode ended last step begin a new one instead."""
        f = self.fleet
        auto = self._autoreset
        if auto.any():
            rows = np.flatnonzero(auto)
            f.reset_robots(rows, self._rngs)
            active = np.flatnonzero(~auto)
        else:
            active = f._all
        terminated, truncated = f.step(actions, active)
        reward = f.reward.copy()
        if auto.any():
            reward[auto] = 0.0
            terminated[auto] = False
            truncated[auto] = False
        self._autoreset = terminated | truncated
        return self._obs(), reward, terminated, truncated, {"collided": f.failed & ~auto, "reached": f.reached & ~auto}
