"""``twb replay RUN --out run.gif``: an animated replay of a run (the testbed's video, emulated)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client


def replay(
    run_id: Annotated[int, typer.Argument(help="Run id (see `twb status ID`).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output animated GIF.")] = Path("run.gif"),
    fps: Annotated[int, typer.Option(help="Frames per second.", min=1, max=60)] = 15,
    speed: Annotated[float, typer.Option(help="Experiment seconds per second of animation.", min=0.01)] = 4.0,
    max_frames: Annotated[int, typer.Option(help="At most this many frames (speed rises to fit).", min=2)] = 300,
    dpi: Annotated[int, typer.Option(help="Resolution of the frames.", min=20, max=300)] = 80,
    robot: Annotated[Optional[int], typer.Option("--robot", help="A multi-robot run: replay this robot (default 0).", min=0)] = None,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Animated replay of a run over its environment: planned path, performed path, robot with heading, and the
    environment's moving obstacles where they were."""
    if out.suffix.lower() != ".gif":
        fail(f"--out must be a .gif file (written with Pillow), got {out}")
    with sdk_client(url, token) as client:
        run = client.get_run(run_id)
        exp = client.get_experiment(run.experiment_id)
        env = client.get_environment(exp.environment)
        fleet, k = exp.robots is not None, robot or 0
        if robot is not None and not fleet:
            fail(f"run {run_id} is a single robot's; --robot is for multi-robot runs")
        if fleet and k >= len(exp.robots):
            fail(f"run {run_id} has {len(exp.robots)} robots (0 to {len(exp.robots) - 1}); --robot {k} is none")
        poses = client.get_poses(run_id, robot=k) if fleet else client.get_poses(run_id)
    planned = exp.planned_path
    if fleet:  # robot k's poses and plan (every robot's plan is in the experiment's planning info)
        import numpy as np

        plans = (exp.planning_info or {}).get("robots") or []
        planned = np.asarray(plans[k]["path"], dtype=float) if k < len(plans) else None
        poses = poses[:, :4]
        if robot is None:
            typer.echo(f"run {run_id} is a multi-robot run of {len(exp.robots)} robots: replaying robot 0 "
                       "(--robot K for another)", err=True)
    if len(poses) == 0:
        fail(f"run {run_id} ({run.status}) has no logged poses to replay")
    from matplotlib.animation import PillowWriter

    from client_sdk.study import replay_animation
    from client_sdk.study._figures import COLORS

    title = (f"run {run.id}: {exp.environment} · {exp.planner or 'path'} · {run.mode} #{run.repetition} "
             f"({run.status})" + (f" · robot {k}" if fleet else ""))
    fig, anim, n = replay_animation(env.to_json(), poses, planned=planned,
                                    robot_radius=exp.robot_radius or 0.045, fps=fps, speed=speed,
                                    max_frames=max_frames, title=title, color=COLORS.get(run.mode, "#d62728"),
                                    obstacle_t0=run.t_start)
    out.parent.mkdir(parents=True, exist_ok=True)
    anim.save(out, writer=PillowWriter(fps=fps), dpi=dpi)
    typer.echo(f"{out}: {n} frames, {n / fps:.1f} s")
