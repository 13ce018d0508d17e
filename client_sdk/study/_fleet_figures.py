"""A fleet study's figures: fleet metrics against the robot count, and every robot's path of a fleet's runs.

Like the other figures they are ``matplotlib.figure.Figure`` objects built
from a :class:`~client_sdk.study.StudyData` alone (offline, no pyplot), and
failures are shown, not dropped: the success rate counts every counted run,
a configuration without a completed run says so in the panel, and a robot
that did not arrive ends in a ✕.
"""

from __future__ import annotations

import textwrap
from typing import Any, Optional

import numpy as np

from contract.vocabulary import JUDGED, Mode

from ._data import StudyData
from ._figures import COLORS, MAX_PATH_ROWS, SHORT, draw_environment, legend_and_title
from ._fleet_results import FLEET_METRICS, FleetGroup, fleet_groups
from ._obstacle_paths import OBSTACLE_STYLE, draw_obstacles
from ._verdict import display_name

__all__ = ["FLEET_FIGURE_METRICS", "TOUCH_M", "figure_fleet_metrics", "figure_fleet_paths", "robot_colours"]

#: rows of the metrics-against-robot-count figure: (metric, y label); ``success_rate``: every robot arrived
FLEET_FIGURE_METRICS = (
    ("success_rate", "runs in which every robot arrived"),
    ("makespan_s", "makespan (s), completed runs"),
    ("robot_distance_min_m", "closest approach of two robots (m),\nevery measured run"),
)
#: two BeBots touch at this centre distance (m): twice the collision radius
TOUCH_M = 0.08
_MODE_STYLE = {"twb": ("-", "o"), "sim": ("--", "s")}


def robot_colours(n: int) -> list[str]:
    """A colour per robot: matplotlib's ``tab10`` cycle up to 10 robots, ``tab20`` beyond."""
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(k % cmap.N) for k in range(n)]


def _point(g: FleetGroup, metric: str) -> tuple[Optional[float], Optional[float], Optional[float]]:
    """A group's value of ``metric`` with its 95% interval (None where there is none)."""
    if metric == "success_rate":
        s = g.success
        return s.get("rate"), s.get("ci_low"), s.get("ci_high")
    s = g.metrics[metric]
    return s.get("mean"), s.get("ci_low"), s.get("ci_high")


def figure_fleet_metrics(data: StudyData, groups: Optional[list[FleetGroup]] = None):  # type: ignore[no-untyped-def]
    """Fleet metrics against the number of robots: rows :data:`FLEET_FIGURE_METRICS`, columns the environments;
    a line per configuration (its colour) and mode (field solid, simulation dashed), 95% intervals as whiskers
    (Wilson for the success rate, Student-t for the means; none where one distinct run is all there is)."""
    from matplotlib.figure import Figure

    groups = groups if groups is not None else fleet_groups(data)
    envs = list(dict.fromkeys(g.environment for g in groups))
    configs = data.configurations
    modes = sorted(data.modes, key=lambda m: m != Mode.TWB)
    lines = [(c, m) for c in configs for m in modes]
    fig = Figure(figsize=(4.2 * len(envs) + 1, 3.0 * len(FLEET_FIGURE_METRICS) + 1.2), layout="constrained")
    axes = np.asarray(fig.subplots(len(FLEET_FIGURE_METRICS), len(envs), squeeze=False, sharex=True))
    counts = sorted({g.robots for g in groups})
    for j, env in enumerate(envs):
        for i, (metric, label) in enumerate(FLEET_FIGURE_METRICS):
            ax = axes[i, j]
            missing = []
            for k, (config, mode) in enumerate(lines):
                mine = sorted((g for g in groups if (g.environment, g.configuration, g.mode) == (env, config, mode)),
                              key=lambda g: g.robots)
                pts = [(g.robots, *_point(g, metric)) for g in mine]
                gone = [str(p[0]) for p in pts if p[1] is None]
                pts = [p for p in pts if p[1] is not None]
                if gone:
                    missing.append(f"{display_name(config)} {SHORT.get(mode, mode)} ({', '.join(gone)})")
                if not pts:
                    continue
                n, y, lo, hi = (np.array([np.nan if v is None else v for v in col], dtype=float) for col in zip(*pts))
                x = n * (1 + 0.04 * (k - (len(lines) - 1) / 2))  # side by side, so the whiskers do not hide
                ls, marker = _MODE_STYLE.get(mode, ("-", "o"))
                colour = f"C{configs.index(config) % 10}"
                ax.plot(x, y, ls=ls, marker=marker, color=colour, ms=5,
                        label=f"{display_name(config)} · {SHORT.get(mode, mode)}")
                has = ~np.isnan(lo)
                ax.errorbar(x[has], y[has], yerr=[y[has] - lo[has], hi[has] - y[has]], fmt="none", ecolor=colour,
                            capsize=3, lw=1)
            if metric == "success_rate":
                ax.set_ylim(-0.05, 1.05)
            if metric == "robot_distance_min_m":
                ax.axhline(TOUCH_M, color="k", lw=0.8, ls=":", label=f"robots touch ({TOUCH_M:g} m)")
            if missing:
                spec = FLEET_METRICS.get(metric)
                what = "no completed run" if spec is not None and spec.over == "completed" else "no counted run"
                ax.text(0.02, 0.97, textwrap.fill(f"{what} (robots): " + ", ".join(missing), 70),
                        transform=ax.transAxes, va="top", fontsize=7, color="0.3")
                low, high = ax.get_ylim()
                ax.set_ylim(low, high + 0.3 * (high - low))  # room for the note above the lines
            ax.set_xscale("log", base=2)
            ax.set_xticks(counts, [str(c) for c in counts])
            ax.minorticks_off()
            ax.grid(color="0.9")
            ax.set_axisbelow(True)
            if j == 0:
                ax.set_ylabel(label, fontsize=9)
            if i == 0:
                ax.set_title(env)
            if i == len(FLEET_FIGURE_METRICS) - 1:
                ax.set_xlabel("robots")
    handles = {lab: h for ax in axes.ravel() for h, lab in zip(*ax.get_legend_handles_labels())}
    legend_and_title(fig, handles, f"Study {data.spec.name}: fleet metrics against the number of robots (S = "
                                   "simulation, T = Teleworkbench; whiskers: 95% intervals over the distinct runs)")
    return fig


def _first_run(data: StudyData, exp: dict[str, Any], mode: str) -> Optional[dict[str, Any]]:
    """The experiment's driven run of lowest repetition in ``mode`` (completed or failed), or None."""
    ids = set(exp.get("runs") or [])
    mine = [r for r in data.rows if r["run_id"] in ids and r["mode"] == mode and r.get("status") in JUDGED]
    return min(mine, key=lambda r: r["repetition"]) if mine else None


def _draw_fleet_run(ax, data: StudyData, exp: dict[str, Any], row: dict[str, Any]) -> None:  # type: ignore[no-untyped-def]
    """Every robot of one run in its colour: planned path dashed, driven path solid, start ○, goal ☆, and a ✕
    where a robot that did not arrive stopped."""
    robots = exp.get("robots") or []
    colours = robot_colours(len(robots))
    planned = exp.get("planned_paths") or [None] * len(robots)
    poses = data.poses(row["run_id"])
    ends = (row.get("robot_ends") or "").split()
    for k, (robot, colour) in enumerate(zip(robots, colours)):
        if k < len(planned) and planned[k]:
            pp = np.asarray(planned[k], dtype=float)
            ax.plot(pp[:, 0], pp[:, 1], ls="--", lw=0.8, color=colour, alpha=0.8)
        mine = poses[poses[:, 4] == k] if poses.ndim == 2 and poses.shape[1] == 5 else np.empty((0, 4))
        if len(mine):
            ax.plot(mine[:, 1], mine[:, 2], lw=1.4, color=colour)
        ax.plot(*robot["start"][:2], "o", color=colour, ms=4, mec="k", mew=0.4)
        ax.plot(*robot["goal"][:2], "*", color=colour, ms=8, mec="k", mew=0.4)
        if k < len(ends) and ends[k] != "arrived" and len(mine):
            ax.plot(mine[-1, 1], mine[-1, 2], "x", color=colour, ms=9, mew=2.4)
            ax.plot(mine[-1, 1], mine[-1, 2], "x", color="k", ms=9, mew=0.6)
    arrived = row.get("robots_arrived")
    note = f"{row.get('fleet_outcome') or row.get('outcome')}"
    if arrived is not None:
        note += f"; {arrived}/{len(robots)} arrived"
    ax.text(0.02, 0.98, note, transform=ax.transAxes, ha="left", va="top", fontsize=7, color="0.15",
            bbox={"facecolor": "white", "alpha": 0.8, "lw": 0, "pad": 1.5})


def figure_fleet_paths(data: StudyData, *, max_rows: int = MAX_PATH_ROWS):  # type: ignore[no-untyped-def]
    """Every robot of a fleet's run, each in its colour (planned dashed, driven solid, ✕ where one that did not
    arrive stopped), with the moving obstacles: where the tracker saw a field run's obstacle robots
    (:meth:`StudyData.obstacles`, dash-dot), else their exact tracks (dotted); rows: problems (environment x
    plan, the first ``max_rows``), columns: configuration x mode; each panel the run of lowest repetition."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    problems, configs = data.problems[:max_rows], data.configurations
    modes = sorted(data.modes, key=lambda m: m != Mode.TWB)
    cols = [(c, m) for c in configs for m in modes]
    fig = Figure(figsize=(2.9 * len(cols), 3.0 * len(problems) + 0.8), layout="constrained")
    axes = np.asarray(fig.subplots(len(problems), len(cols), squeeze=False))
    by_key = {(e["environment"], e["plan"], e["configuration"]): e for e in data.experiments}
    kinds: set[Optional[str]] = set()  # the moving obstacles' kinds drawn, for the legend
    for i, (env_name, plan) in enumerate(problems):
        env = data.environments[env_name]
        for j, (config, mode) in enumerate(cols):
            ax = axes[i, j]
            draw_environment(ax, env)
            exp = by_key.get((env_name, plan, config))
            ax.set_title(f"{env_name} {plan} · {display_name(config)} · {SHORT.get(mode, mode)}", fontsize=8)
            row = _first_run(data, exp, mode) if exp is not None else None
            if row is None:
                ax.text(0.5, 0.5, "refused by the testbed" if exp and exp["status"] == "rejected" else "no run",
                        transform=ax.transAxes, ha="center", color=COLORS["failed"], fontsize=8)
                continue
            t_end = row.get("t_end") if isinstance(row.get("t_end"), (int, float)) else 0.0
            kinds.add(draw_obstacles(ax, env, float(t_end), data.obstacles(row["run_id"])))
            _draw_fleet_run(ax, data, exp, row)
    handles = {"planned (dashed, the robot's colour)": Line2D([], [], ls="--", color="0.3", lw=0.8),
               "driven": Line2D([], [], color="0.3", lw=1.4),
               "start": Line2D([], [], ls="none", marker="o", color="0.5", mec="k"),
               "goal": Line2D([], [], ls="none", marker="*", color="0.5", mec="k", ms=9),
               "did not arrive (where it stopped)": Line2D([], [], ls="none", marker="x", color="k", mew=2),
               **{what: Line2D([], [], **style) for what, style in OBSTACLE_STYLE.items() if what in kinds}}
    more = f" (the first {len(problems)} of {len(data.problems)} problems)" if len(problems) < len(data.problems) \
        else ""
    legend_and_title(fig, handles, f"Study {data.spec.name}: every robot's path, each robot in its colour, of the "
                                   f"first run per configuration and mode{more}", fontsize=8)
    return fig
