"""An animated replay of one run over its environment: our stand-in for the testbed's recorded video."""

from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

from ._figures import COLORS, draw_environment

__all__ = ["replay_animation"]


def replay_animation(env: dict[str, Any], poses: np.ndarray, *, planned: Optional[np.ndarray] = None,
                     robot_radius: float = 0.045, fps: int = 15, speed: float = 4.0, max_frames: int = 300,
                     title: str = "", color: str = COLORS["twb"]):  # type: ignore[no-untyped-def]
    """A matplotlib ``FuncAnimation`` of a run: planned path, performed path so far, robot with heading.

    Parameters
    ----------
    env : environment file (docs/design.md, "Environment file") the run was made in
    poses : (N, 4) float array, s, m, m, rad
        Logged poses t, x, y, theta, oldest first.
    planned : (M, 2|3) float array, m, optional
    robot_radius : float, m
    fps : int
        Frames per second of the animation.
    speed : float
        Experiment seconds per animation second (raised when the run would
        need more than ``max_frames`` frames).

    Returns
    -------
    (Figure, FuncAnimation, n_frames)
        Save with ``anim.save("run.gif", writer=PillowWriter(fps=fps))``.
    """
    from matplotlib.animation import FuncAnimation
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    p = np.asarray(poses, dtype=float).reshape(-1, 4)
    if len(p) < 1:
        raise ValueError("`poses` is empty: the run logged no pose to replay")
    if not (fps >= 1 and speed > 0 and max_frames >= 2):
        raise ValueError("`fps` must be >= 1, `speed` > 0 and `max_frames` >= 2")
    t0, t1 = float(p[0, 0]), float(p[-1, 0])
    dt = speed / fps
    n = int(math.floor((t1 - t0) / dt)) + 1
    if n > max_frames:
        dt, n = (t1 - t0) / (max_frames - 1), max_frames
    times = t0 + dt * np.arange(n)
    idx = np.minimum(np.searchsorted(p[:, 0], times, side="right") - 1, len(p) - 1).clip(0)
    idx = np.append(idx, [len(p) - 1] * max(1, fps // 2))  # hold the last pose for half a second

    fig = Figure(figsize=(5, 5.3), layout="constrained")
    ax = fig.subplots()
    draw_environment(ax, env)
    if planned is not None and len(planned):
        pl = np.asarray(planned, dtype=float)
        ax.plot(pl[:, 0], pl[:, 1], "k--", lw=1, label="planned")
    (trace,) = ax.plot([], [], color=color, lw=1.5, label="performed")
    robot = Circle((p[0, 1], p[0, 2]), robot_radius, fc=color, ec="k", alpha=0.6)
    ax.add_patch(robot)
    (heading,) = ax.plot([], [], "k-", lw=1.5)
    clock = ax.text(0.06, 0.96, "", transform=ax.transAxes, va="top", fontsize=9,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.7})
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title, fontsize=10)

    def update(k: int):  # type: ignore[no-untyped-def]
        i = int(idx[k])
        x, y, a = p[i, 1], p[i, 2], p[i, 3]
        trace.set_data(p[: i + 1, 1], p[: i + 1, 2])
        robot.center = (x, y)
        heading.set_data([x, x + robot_radius * 1.6 * math.cos(a)], [y, y + robot_radius * 1.6 * math.sin(a)])
        clock.set_text(f"t = {p[i, 0] - t0:5.1f} s")
        return trace, robot, heading, clock

    anim = FuncAnimation(fig, update, frames=len(idx), interval=1000 / fps, blit=False)
    return fig, anim, len(idx)
