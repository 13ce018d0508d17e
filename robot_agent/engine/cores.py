"""A simulation core on the field's standard layout: robots, their backend and their worlds built the one way
every headless run, benchmark and test builds them."""

from __future__ import annotations

from contract.frames import field_layout
from contract.params import RobotParams

from .backends import make_backend
from .sim import SimCore
from .world import World

__all__ = ["layout_core"]


def layout_core(params: RobotParams, backend: str, n: int = 1, mode: str = "separate",
                area: tuple[float, float] | list[tuple[float, float]] | None = None, *,
                log_poses: bool = True) -> SimCore:
    """A :class:`SimCore` of ``n`` robots of ``params`` on ``backend`` (``"ideal"`` or ``"field"``), in the worlds
    :func:`contract.frames.field_layout` gives for ``mode`` and ``area`` (m; default a 1.8 m sub-field each),
    with nothing built or placed yet."""
    sizes, world_of, origin, areas = field_layout(n, mode, area)
    world = World(sizes, world_of, origin, areas, params.collision_radius_m)
    return SimCore(params, make_backend(backend, n, params), world, log_poses=log_poses)
