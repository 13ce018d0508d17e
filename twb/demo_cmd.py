"""``twb demo``: plan the paper's environments with every built-in planner and print a table."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

import typer

from .plan_cmd import PlanningMarginOpt, RobotRadiusOpt

if TYPE_CHECKING:
    from planners import Environment, PlanResult


def demo(
    seed: Annotated[int, typer.Option(help="Seed for PRM.", min=0)] = 0,
    resolution: Annotated[float, typer.Option(help="Grid resolution, metres per cell.")] = 0.01,
    robot_radius: RobotRadiusOpt = None,
    planning_margin: PlanningMarginOpt = None,
) -> None:
    """Plan both built-in environments x both start/goal plans with FMM, FM2, PRM and A*, as the testbed plans."""
    from rich.console import Console
    from rich.table import Table

    from planners import load_environment, plan_path

    from .plan_cmd import clearance, clearance_words

    radius, margin = clearance(robot_radius, planning_margin)
    table = Table(title=f"Planning demo ({clearance_words(radius, margin)}, BeBot)")
    for col in ("environment", "plan", "planner", "length m", "min clearance m", "points", "planning ms"):
        table.add_column(col, justify="right" if col not in ("environment", "plan", "planner") else "left")
    for name in ("room", "blocks"):
        env = load_environment(name)
        for p in env.plans:
            for planner in ("fmm", "fm2", "prm", "astar"):
                r = plan_path(env, p.start, p.goal, planner, seed=seed, resolution=resolution, robot_radius=radius,
                              planning_margin=margin)
                table.add_row(name, p.name, planner, f"{r.length_m:.3f}", f"{path_clearance(env, r):.3f}",
                              str(len(r.path)), f"{r.planning_time_s * 1000:.1f}")
    Console().print(table)
    typer.echo("Next: `twb plan --env room --plan A --planner fm2 --format ttp` prints the T,T,P line for a robot.")


def path_clearance(env: "Environment", result: "PlanResult", step_m: float = 0.001) -> float:
    """Smallest distance (m) from the path to any block or wall, sampled every ``step_m`` metres
    with the exact geometry."""
    import numpy as np

    from planners import distance_to_obstacles

    path = result.path
    seg = np.diff(path[:, :2], axis=0)
    n = max(int(result.length_m / step_m), 2)
    s = np.linspace(0, 1, n)
    cum = np.r_[0, np.cumsum(np.hypot(*seg.T))] / result.length_m
    pts = np.column_stack([np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])])
    return float(distance_to_obstacles(env, pts).min())
