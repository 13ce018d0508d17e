"""``twb plan`` and ``twb planners``: plan a path from the shell (docs/design.md, "Command line")."""

from __future__ import annotations

import json
import math
import sys
from enum import Enum
from typing import Annotated, Optional

import typer

from .errors import fail
from .poses import parse_cli_pose

#: the configuration space's options of ``twb plan`` and ``twb demo``: as the testbed plans unless told
RobotRadiusOpt = Annotated[Optional[float], typer.Option(
    help="Robot radius in metres (default: the BeBot profile's, 0.045).")]
PlanningMarginOpt = Annotated[Optional[float], typer.Option(
    help="Clearance kept beyond the robot radius, metres; 0 for none (default: the testbed's, 0.02).")]


class PlanFormat(str, Enum):
    json = "json"
    ttp = "ttp"
    csv = "csv"


def _params(items: list[str], flag: str = "--param") -> dict:
    out: dict = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            fail(f"{flag} must be NAME=VALUE, got {item!r}")
        try:
            out[key.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            out[key.strip()] = raw
    return out


def plan(
    env: Annotated[str, typer.Option("--env", help="Built-in environment name (room, blocks, crossing, swap) or a "
                                                   "JSON file.")],
    start: Annotated[Optional[str], typer.Option(help="Start X,Y[,A]: metres; A in radians or e.g. 90deg.")] = None,
    goal: Annotated[Optional[str], typer.Option(help="Goal X,Y[,A]: metres; A in radians or e.g. 90deg.")] = None,
    plan_name: Annotated[
        Optional[str], typer.Option("--plan", help="Use the environment's named start/goal plan (e.g. A).")
    ] = None,
    planner: Annotated[str, typer.Option(help="fmm, fm2, prm, astar, st_astar, theta_star, ompl_rrtconnect, "
                                                  "ompl_rrtstar, ompl_informed_rrtstar, ompl_bitstar, ompl_prmstar, "
                                                  "ompl_kpiece1, ompl_fmt (the ompl extra) or a plug-in name "
                                                  "(twb planners).")] = "fmm",
    seed: Annotated[int, typer.Option(help="Seed for randomised planners (PRM, OMPL's).", min=0)] = 0,
    robot_radius: RobotRadiusOpt = None,
    planning_margin: PlanningMarginOpt = None,
    resolution: Annotated[float, typer.Option(help="Grid resolution in metres per cell.")] = 0.01,
    max_spacing: Annotated[float, typer.Option(help="Largest distance between path points, metres.")] = 0.1,
    param: Annotated[
        Optional[list[str]], typer.Option("--param", "-p", help="Planner parameter NAME=VALUE (repeatable).")
    ] = None,
    fmt: Annotated[PlanFormat, typer.Option("--format", help="json, ttp (wire line, mm/deg) or csv.")] = PlanFormat.json,
) -> None:
    """Plan a collision-free path and print it (JSON, a T,T,P line, or CSV t,x,y,theta).

    It plans as the testbed does: obstacles dilated by the robot radius plus the planning
    margin.  JSON carries both (robot_radius_m, planning_margin_m); with ttp and csv a comment
    line on stderr says them.
    """
    from contract.protocol import encode_path
    from planners import load_environment, plan_path

    environment = load_environment(env)
    if plan_name is not None:
        if start or goal:
            fail("give either --plan or --start/--goal, not both")
        try:
            p = environment.plan(plan_name)
        except KeyError as exc:
            fail(str(exc.args[0]))
        s, g = list(p.start), list(p.goal)
    else:
        if not start or not goal:
            fail("--start and --goal are required (or --plan NAME for a built-in start/goal pair)")
        s, g = parse_cli_pose(start, "start"), parse_cli_pose(goal, "goal")
    radius, margin = clearance(robot_radius, planning_margin)
    result = plan_path(
        environment, s, g, planner, robot_radius=radius, resolution=resolution,
        params=_params(param or []), seed=seed, max_spacing=max_spacing, planning_margin=margin,
    )
    out = sys.stdout
    if fmt is PlanFormat.json:
        doc = result.to_dict()
        doc.update(environment=environment.name, start=s, goal=g, resolution_m=resolution)
        json.dump(doc, out)
        out.write("\n")
        return
    typer.echo(f"# {result.planner} on {environment.name}: {result.length_m:.3f} m, planned for {clearance_words(radius, margin)}",
               err=True)
    if fmt is PlanFormat.ttp:
        out.write(encode_path(result.path) + "\n")
    else:
        out.write("t,x,y,theta\n")
        for x, y, a in result.path.tolist():
            out.write(f",{x:.6f},{y:.6f},{a:.6f}\n")


def clearance(robot_radius: Optional[float], planning_margin: Optional[float]) -> tuple[float, float]:
    """The robot radius and planning margin (m) to plan with: the options, else the testbed's defaults
    (the BeBot profile's radius, :data:`planners.DEFAULT_PLANNING_MARGIN`)."""
    from contract.robot_profile import load_profile
    from planners import DEFAULT_PLANNING_MARGIN

    radius = load_profile()["radius_m"] if robot_radius is None else robot_radius
    margin = DEFAULT_PLANNING_MARGIN if planning_margin is None else planning_margin
    if not math.isfinite(radius) or radius < 0:
        fail(f"--robot-radius must be a finite number >= 0, got {radius}")
    if not math.isfinite(margin) or margin < 0:
        fail(f"--planning-margin must be a finite number >= 0 (0: none), got {margin}")
    return radius, margin


def clearance_words(radius: float, margin: float) -> str:
    """``"robot radius 0.045 m + planning margin 0.02 m"`` (metres)."""
    return f"robot radius {radius:g} m + planning margin {margin:g} m"


def planners() -> None:
    """List the planners that --planner accepts (built-ins and installed plug-ins)."""
    from planners import available_planners

    listed = available_planners()
    width = max(map(len, listed), default=10)
    for name, desc in listed.items():
        typer.echo(f"{name:{width}s} {desc}")
