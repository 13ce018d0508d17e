"""An animated replay of a run over its environment (every robot, every moving obstacle): our stand-in for the
testbed's recorded video."""

from __future__ import annotations

import math
from typing import Any, Optional, Sequence

import numpy as np

from ._figures import COLORS, draw_environment
from ._obstacle_paths import obstacle_paths

__all__ = ["replay_animation"]


def replay_animation(env: dict[str, Any], poses: np.ndarray | Sequence[np.ndarray], *,
                     planned: Optional[np.ndarray | Sequence[Optional[np.ndarray]]] = None,
                     robot_radius: float = 0.045, fps: int = 15, speed: float = 4.0, max_frames: int = 300,
                     title: str = "", color: str = COLORS["twb"],
                     obstacle_t0: Optional[float] = None,
                     obstacles: Optional[Sequence[np.ndarray]] = None,
                     obstacle_radii: Optional[Sequence[float]] = None):  # type: ignore[no-untyped-def]
    """A matplotlib ``FuncAnimation`` of a run: planned paths, performed paths so far, every robot with its
    heading, and the environment's moving obstacles where they were at each frame: on their exact tracks, or
    where the tracker saw a field run's obstacle robots (``obstacles``); the legend says which.

    Parameters
    ----------
    env : environment file (docs/design.md, "Environment file") the run was made in
    poses : (N, 4) float array, or one such array per robot of a multi-robot run; s, m, m, rad
        Logged poses t, x, y, theta, oldest first (one clock for all robots).
    planned : (M, 2|3) float array, or one per robot (None where there is none), m, optional
    robot_radius : float, m
    fps : int
        Frames per second of the animation.
    speed : float
        Experiment seconds per animation second (raised when the run would
        need more than ``max_frames`` frames; the last poses are then held for
        half a second more, ``fps // 2`` frames, at least one).
    color : the robot's colour (one robot; several get a colour each)
    obstacle_t0 : float, s, optional
        The pose time at which the moving obstacles' clock is 0 (a run's ``t_start``: obstacles move
        from its path's start); default the first pose's time.  Not used with ``obstacles``.
    obstacles : sequence of (T, 4) float arrays, s, m, m, rad, optional
        Where each moving obstacle was, on the poses' clock (a field run's obstacle robots as the tracker
        saw them, :meth:`client_sdk.Client.get_obstacles`), interpolated at each frame; default the
        environment's exact tracks.
    obstacle_radii : sequence of float, m, optional
        The radius each of ``obstacles`` is drawn with; default the environment's.

    Returns
    -------
    (Figure, FuncAnimation, n_frames)
        Save with ``anim.save("run.gif", writer=PillowWriter(fps=fps))``.
    """
    from matplotlib.animation import FuncAnimation
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    several = not isinstance(poses, np.ndarray)
    tracks = [np.asarray(q, dtype=float).reshape(-1, 4) for q in (poses if several else [poses])]
    if not tracks or all(len(q) == 0 for q in tracks):
        raise ValueError("`poses` is empty: the run logged no pose to replay")
    if not (fps >= 1 and speed > 0 and max_frames >= 2):
        raise ValueError("`fps` must be >= 1, `speed` > 0 and `max_frames` >= 2")
    plans = list(planned) if several and planned is not None else [planned] * (1 if not several else len(tracks))
    t0 = min(float(q[0, 0]) for q in tracks if len(q))
    t1 = max(float(q[-1, 0]) for q in tracks if len(q))
    dt = speed / fps
    n = int(math.floor((t1 - t0) / dt)) + 1
    if n > max_frames:
        dt, n = (t1 - t0) / (max_frames - 1), max_frames
    times = t0 + dt * np.arange(n)
    times = np.append(times, [t1] * max(1, fps // 2))  # hold the last poses for half a second
    idx = [np.minimum(np.searchsorted(q[:, 0], times, side="right") - 1, len(q) - 1).clip(0) for q in tracks]
    at = times if obstacles is not None else times - (t0 if obstacle_t0 is None else obstacle_t0)
    centres, radii, what = obstacle_paths(env, at, obstacles, obstacle_radii)

    fig = Figure(figsize=(5, 5.3), layout="constrained")
    ax = fig.subplots()
    draw_environment(ax, env)
    colours = [color] if len(tracks) == 1 else [f"C{i % 10}" for i in range(len(tracks))]
    artists: list[tuple[Any, Any, Any]] = []
    for i, (q, c) in enumerate(zip(tracks, colours)):
        pl = plans[i] if i < len(plans) else None
        if pl is not None and len(pl):
            pl = np.asarray(pl, dtype=float)
            ax.plot(pl[:, 0], pl[:, 1], "--", color="k" if len(tracks) == 1 else c, lw=1,
                    label="planned" if i == 0 else None)
        label = "performed" if len(tracks) == 1 else f"robot {i}"
        (trace,) = ax.plot([], [], color=c, lw=1.5, label=label)
        first = q[0] if len(q) else np.full(4, np.nan)
        robot = Circle((first[1], first[2]), robot_radius, fc=c, ec="k", alpha=0.6)
        ax.add_patch(robot)
        (heading,) = ax.plot([], [], "k-", lw=1.5)
        artists.append((trace, robot, heading))
    discs = [Circle(tuple(centres[m][0]), r, fc="#7f7f7f", ec="k", hatch="//", alpha=0.8,
                    label=what if m == 0 else None) for m, r in enumerate(radii)]
    for d in discs:
        ax.add_patch(d)
    clock = ax.text(0.06, 0.96, "", transform=ax.transAxes, va="top", fontsize=9,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.7})
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title, fontsize=10)

    def update(k: int):  # type: ignore[no-untyped-def]
        out: list[Any] = [clock]
        for q, ix, (trace, robot, heading) in zip(tracks, idx, artists):
            if not len(q):
                continue
            i = int(ix[k])
            x, y, a = q[i, 1], q[i, 2], q[i, 3]
            trace.set_data(q[: i + 1, 1], q[: i + 1, 2])
            robot.center = (x, y)
            heading.set_data([x, x + robot_radius * 1.6 * math.cos(a)], [y, y + robot_radius * 1.6 * math.sin(a)])
            out += [trace, robot, heading]
        for m, d in enumerate(discs):
            d.center = tuple(centres[m][k])
            out.append(d)
        clock.set_text(f"t = {times[k] - t0:5.1f} s")
        return out

    anim = FuncAnimation(fig, update, frames=len(times), interval=1000 / fps, blit=False)
    return fig, anim, len(times)
