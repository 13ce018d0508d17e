"""Path planning for the Teleworkbench: environments, occupancy grids, planners, post-processing.

numpy/scipy/scikit-fmm, and numba for the compiled kernels (fast marching,
Theta*, the segment test of PRM and OMPL's planners; loaded with the first
plan that needs them); imports nothing else of the project.  Units are
metres and radians throughout.

>>> from planners import plan_path
>>> result = plan_path("room", (0.3, 0.3, 0.0), (1.5, 1.5, 1.57), "fm2")
>>> result.path.shape[1]
3
"""

from .api import DEFAULT_PLANNING_MARGIN, DEFAULT_ROBOT_RADIUS, PlanResult, check_query, parse_pose, plan_path
from .base import Param, Planner
from .environment import Block, Environment, Plan, builtin_names, load_environment, parse_environment
from .errors import InvalidEnvironment, InvalidPose, NoPathFound, PlanningError, UnknownPlanner
from .geometry import distance_to_obstacles, signed_distance_to_blocks
from .grid import ConfigSpace, GridMap, config_space, grid_map
from .registry import ENTRY_POINT_GROUP, available_planners, get_planner, register_planner

__all__ = sorted(
    [
        "Block",
        "ConfigSpace",
        "DEFAULT_PLANNING_MARGIN",
        "DEFAULT_ROBOT_RADIUS",
        "ENTRY_POINT_GROUP",
        "Environment",
        "GridMap",
        "InvalidEnvironment",
        "InvalidPose",
        "NoPathFound",
        "Param",
        "Plan",
        "PlanResult",
        "Planner",
        "PlanningError",
        "UnknownPlanner",
        "available_planners",
        "check_query",
        "builtin_names",
        "config_space",
        "distance_to_obstacles",
        "get_planner",
        "grid_map",
        "load_environment",
        "parse_environment",
        "parse_pose",
        "plan_path",
        "register_planner",
        "signed_distance_to_blocks",
    ]
)
