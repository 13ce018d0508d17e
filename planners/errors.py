"""Exceptions raised by the planning package.

Every error a user can cause is a subclass of :class:`PlanningError` (itself a
``ValueError``), and its message names what is wrong so that a command line or
REST layer can show it as one line::

    PlanningError (ValueError)
     ├── InvalidEnvironment   environment JSON/file is unreadable or invalid
     ├── InvalidPose          start/goal outside the field, NaN, or inside an obstacle
     ├── NoPathFound          start and goal are not connected in free space
     └── UnknownPlanner       no built-in or plug-in planner has that name
"""

from __future__ import annotations

__all__ = [
    "InvalidEnvironment",
    "InvalidPose",
    "NoPathFound",
    "PlanningError",
    "UnknownPlanner",
]


class PlanningError(ValueError):
    """Base class of all user-facing planning errors."""


class InvalidEnvironment(PlanningError):
    """The environment description is unreadable or violates the schema."""


class InvalidPose(PlanningError):
    """A start or goal pose is not finite, outside the field, or not free."""


class NoPathFound(PlanningError):
    """No collision-free path connects start and goal."""


class UnknownPlanner(PlanningError):
    """No planner is registered under the requested name."""
