"""``twb replay RUN --out run.gif``: an animated replay of a run (the testbed's video, emulated)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client


def replay(
    run_id: Annotated[int, typer.Argument(help="Run id (see `twb status ID`).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output animated GIF.")] = Path("run.gif"),
    fps: Annotated[int, typer.Option(help="Frames per second.", min=1, max=60)] = 15,
    speed: Annotated[float, typer.Option(help="Experiment seconds per second of animation.", min=0.01)] = 4.0,
    max_frames: Annotated[int, typer.Option(help="At most this many frames over the run (speed rises to fit), then half a second holding the end.", min=2)] = 300,
    dpi: Annotated[int, typer.Option(help="Resolution of the frames.", min=20, max=300)] = 80,
    robot: Annotated[Optional[int], typer.Option("--robot", help="A multi-robot run: only this robot (default: every robot).", min=0)] = None,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Animated replay of a run over its environment: planned path, performed path, robot with heading, and the
    environment's moving obstacles where they were (a field run's obstacle robots as the tracker saw them;
    else their exact tracks)."""
    if out.suffix.lower() != ".gif":
        fail(f"--out must be a .gif file (written with Pillow), got {out}")
    with sdk_client(url, token) as client:
        run = client.get_run(run_id)
        exp = client.get_experiment(run.experiment_id)
        env = client.get_environment(exp.environment)
        fleet = exp.robots is not None
        if robot is not None and not fleet:
            fail(f"run {run_id} is a single robot's; --robot is for multi-robot runs")
        if robot is not None and robot >= len(exp.robots):
            fail(f"run {run_id} has {len(exp.robots)} robots (0 to {len(exp.robots) - 1}); --robot {robot} is none")
        poses = client.get_poses(run_id) if robot is None else client.get_poses(run_id, robot=robot)
        obstacles = client.get_obstacles(run_id) if env.moving_obstacles else None
    if len(poses) == 0:
        fail(f"run {run_id} ({run.status}) has no logged poses to replay")
    planned = exp.planned_path
    if fleet:
        poses, planned = _fleet_tracks(exp, poses, robot)
    from matplotlib.animation import PillowWriter

    from client_sdk.study import replay_animation
    from client_sdk.study._figures import COLORS

    title = (f"run {run.id}: {exp.environment} · {exp.planner or 'path'} · {run.mode} #{run.repetition} "
             f"({run.status})" + (f" · robot {robot}" if robot is not None else ""))
    tracked = obstacles is not None and not obstacles.exact
    fig, anim, n = replay_animation(env.to_json(), poses, planned=planned,
                                    robot_radius=exp.robot_radius or 0.045, fps=fps, speed=speed,
                                    max_frames=max_frames, title=title, color=COLORS.get(run.mode, "#d62728"),
                                    obstacle_t0=0.0 if fleet else run.t_start,  # a fleet's obstacles: its clock
                                    obstacles=obstacles.tracks if tracked else None,
                                    obstacle_radii=obstacles.radii if tracked else None)
    out.parent.mkdir(parents=True, exist_ok=True)
    anim.save(out, writer=PillowWriter(fps=fps), dpi=dpi)
    shown = "" if obstacles is None else \
        ("; moving obstacles: the obstacle robots as tracked" if tracked else "; moving obstacles: exact tracks")
    typer.echo(f"{out}: {n} frames, {n / fps:.1f} s{shown}")


def _fleet_tracks(exp: Any, poses: Any, robot: Optional[int]) -> tuple[Any, Any]:
    """A multi-robot run's poses ``(N, 5)`` (t, x, y, theta, robot) and plans as the replay takes them: robot
    ``robot``'s ``(N, 4)`` poses and path, or (None) every robot's in a list (plans: the experiment's
    ``planning_info["robots"]``)."""
    import numpy as np

    plans = [np.asarray(r["path"], dtype=float) for r in (exp.planning_info or {}).get("robots") or []]
    if robot is not None:
        return poses[:, :4], (plans[robot] if robot < len(plans) else None)
    tracks = [poses[poses[:, 4] == k, :4] for k in range(len(exp.robots))]
    return tracks, (plans if len(plans) == len(tracks) else None)
