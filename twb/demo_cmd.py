"""``twb demo``: plan the paper's environments with every built-in planner and print a table."""

from __future__ import annotations

from typing import Annotated

import typer


def demo(
    seed: Annotated[int, typer.Option(help="Seed for PRM.", min=0)] = 0,
    resolution: Annotated[float, typer.Option(help="Grid resolution, metres per cell.")] = 0.01,
) -> None:
    """Plan both built-in environments x both start/goal plans with FMM, FM2, PRM and A*."""
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from planners import distance_to_obstacles, load_environment, plan_path

    table = Table(title="Planning demo (robot radius 0.045 m, BeBot)")
    for col in ("environment", "plan", "planner", "length m", "min clearance m", "points", "planning ms"):
        table.add_column(col, justify="right" if col not in ("environment", "plan", "planner") else "left")
    for name in ("room", "blocks"):
        env = load_environment(name)
        for p in env.plans:
            for planner in ("fmm", "fm2", "prm", "astar"):
                r = plan_path(env, p.start, p.goal, planner, seed=seed, resolution=resolution)
                # clearance along the path, sampled every millimetre with the exact geometry
                seg = np.diff(r.path[:, :2], axis=0)
                n = max(int(r.length_m / 0.001), 2)
                s = np.linspace(0, 1, n)
                cum = np.r_[0, np.cumsum(np.hypot(*seg.T))] / r.length_m
                pts = np.column_stack([np.interp(s, cum, r.path[:, 0]), np.interp(s, cum, r.path[:, 1])])
                clearance = float(distance_to_obstacles(env, pts).min())
                table.add_row(name, p.name, planner, f"{r.length_m:.3f}", f"{clearance:.3f}",
                              str(len(r.path)), f"{r.planning_time_s * 1000:.1f}")
    Console().print(table)
    typer.echo("Next: `twb plan --env room --plan A --planner fm2 --format ttp` prints the T,T,P line for a robot.")
