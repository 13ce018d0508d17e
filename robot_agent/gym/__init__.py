"""Gymnasium environments on the simulation engine (docs/gymnasium.md).

``Teleworkbench/Navigate-v0`` (the emulated field robot) and ``Teleworkbench/NavigateIdeal-v0`` (the
ideal robot): a robot drives to a goal with body velocities, observing its pose, the goal and the local
occupancy (:mod:`robot_agent.gym.envs`), on the engine's own robots and worlds
(:mod:`robot_agent.gym.fleet`).  Both have a vectorised form that steps N robots in one compiled call::

    import gymnasium
    import robot_agent.gym  # noqa: F401 (Gymnasium >= 1.0 loads no plug-ins by itself: this registers)

    env = gymnasium.make("Teleworkbench/Navigate-v0")
    envs = gymnasium.make_vec("Teleworkbench/Navigate-v0", num_envs=1000, vectorization_mode="vector_entry_point")

The project's ``gymnasium.envs`` entry point names :func:`register_envs`.  Importing this package
registers the environments and loads no numba: the engine loads when an environment is made.
"""

from __future__ import annotations

__all__ = ["ENV_IDS", "register_envs"]

#: the registered ids and the engine backend of each
ENV_IDS = {"Teleworkbench/Navigate-v0": "field", "Teleworkbench/NavigateIdeal-v0": "ideal"}


def register_envs() -> None:
    """Register the environments with Gymnasium (again: a no-op); the ``gymnasium.envs`` entry point."""
    from gymnasium.envs.registration import register, registry

    for env_id, backend in ENV_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point="robot_agent.gym.envs:NavigationEnv",
                     vector_entry_point="robot_agent.gym.envs:NavigationVectorEnv", kwargs={"backend": backend},
                     disable_env_checker=False)


try:
    register_envs()
except ImportError:  # gymnasium is an optional dependency (the `gym` extra)
    pass
