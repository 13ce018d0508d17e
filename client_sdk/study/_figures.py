"""The study's figures, after the paper's Fig. 6, 7 and 8, as matplotlib ``Figure`` objects.

Built with ``matplotlib.figure.Figure`` (no pyplot, no global state, any
backend), from a :class:`~client_sdk.study.StudyData` only, so they can be
redrawn offline from a study directory.  Saving is the caller's business
(:func:`save_figures`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterable, Optional

import numpy as np

from ._data import StudyData

__all__ = ["FIG6_METRICS", "FIG7_RATIOS", "figure_metrics", "figure_paths", "figure_ratios", "make_figures",
           "mean_std", "save_figures"]

#: Fig. 6 panels: (metric, label); the planned path's value is shown where it has one
FIG6_METRICS = (
    ("length_m", "path length (m)"),
    ("smoothness_rad", "smoothness κ' (rad)"),
    ("clearance_min_m", "minimum clearance (m)"),
    ("execution_time_s", "execution time (s)"),
    ("average_speed_m_s", "average speed (m/s)"),
    ("deviation_mean_m", "mean deviation (m)"),
)
#: Fig. 7 panels: performed / planned ratios
FIG7_RATIOS = (
    ("length_ratio", "length ratio"),
    ("smoothness_ratio", "smoothness ratio"),
    ("clearance_ratio", "clearance ratio"),
)
COLORS = {"computed": "#7f7f7f", "sim": "#1f77b4", "twb": "#d62728", "direct": "#9467bd"}
LABELS = {"computed": "computed (planned)", "sim": "simulation (S)", "twb": "Teleworkbench (T)",
          "direct": "direct comparison (ST)"}


def mean_std(values: Iterable[Any]) -> tuple[Optional[float], Optional[float], int]:
    """Mean, sample std (ddof 1; None below 2 values) and count of the finite numbers in ``values``."""
    xs = np.array([float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)
                   and math.isfinite(float(v))])
    if xs.size == 0:
        return None, None, 0
    return float(xs.mean()), (float(xs.std(ddof=1)) if xs.size > 1 else None), int(xs.size)


def _completed(data: StudyData) -> list[dict[str, Any]]:
    return [r for r in data.rows if r.get("status") == "completed"]


def _grouped_bars(ax, planners: list[str], series: dict[str, list[tuple[Optional[float], Optional[float]]]]) -> None:  # type: ignore[no-untyped-def]
    kinds = [k for k, vals in series.items() if any(m is not None for m, _ in vals)]
    width = 0.8 / max(len(kinds), 1)
    x = np.arange(len(planners))
    for i, kind in enumerate(kinds):
        means = [m if m is not None else np.nan for m, _ in series[kind]]
        errs = [s if s is not None else 0.0 for _, s in series[kind]]
        ax.bar(x + (i - (len(kinds) - 1) / 2) * width, means, width, yerr=errs, capsize=2,
               color=COLORS[kind], label=LABELS[kind])
    ax.set_xticks(x, [p.upper() if p in ("fmm", "prm") else ("FM²" if p == "fm2" else p) for p in planners])
    ax.grid(axis="y", color="0.9")
    ax.set_axisbelow(True)


def figure_metrics(data: StudyData):  # type: ignore[no-untyped-def]
    """Fig. 6: each metric per planner: computed path, simulation, Teleworkbench, and the direct comparison.

    One panel per :data:`FIG6_METRICS`; bars are means over the completed runs
    of all environments and plans, error bars one standard deviation.
    """
    from matplotlib.figure import Figure

    rows, planners = _completed(data), data.planners
    fig = Figure(figsize=(12, 6.5), layout="constrained")
    axes = fig.subplots(2, 3).ravel()
    for ax, (key, label) in zip(axes, FIG6_METRICS):
        series: dict[str, list] = {k: [] for k in ("computed", "sim", "twb", "direct")}
        for p in planners:
            mine = [r for r in rows if r["planner"] == p]
            planned = {(r["experiment_id"]): r.get(f"planned_{key}") for r in mine}
            series["computed"].append(mean_std(planned.values())[:2] if f"planned_{key}" in _keys(mine) else (None, None))
            for mode in ("sim", "twb"):
                series[mode].append(mean_std(r.get(key) for r in mine if r["mode"] == mode)[:2])
            series["direct"].append(mean_std(d.get(key) for d in data.direct if d["planner"] == p)[:2]
                                    if key == "deviation_mean_m" else (None, None))
        _grouped_bars(ax, planners, series)
        ax.set_title(label)
    handles = {lab: h for ax in axes for h, lab in zip(*ax.get_legend_handles_labels())}
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncols=len(handles), frameon=False)
    fig.suptitle(f"Study {data.spec.name}: metrics per planner (mean ± std over {len(rows)} completed runs)")
    return fig


def _keys(rows: list[dict[str, Any]]) -> set[str]:
    return {k for r in rows for k, v in r.items() if v is not None}


def figure_ratios(data: StudyData):  # type: ignore[no-untyped-def]
    """Fig. 7: performed / planned ratios (length, smoothness, clearance) per planner, sim and twb."""
    from matplotlib.figure import Figure

    rows, planners = _completed(data), data.planners
    fig = Figure(figsize=(12, 3.8), layout="constrained")
    axes = fig.subplots(1, len(FIG7_RATIOS))
    for ax, (key, label) in zip(axes, FIG7_RATIOS):
        series = {mode: [mean_std(r.get(key) for r in rows if r["planner"] == p and r["mode"] == mode)[:2]
                         for p in planners] for mode in ("sim", "twb")}
        _grouped_bars(ax, planners, series)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_title(f"{label} (performed / planned)")
    handles = {lab: h for ax in axes for h, lab in zip(*ax.get_legend_handles_labels())}
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncols=len(handles), frameon=False)
    fig.suptitle(f"Study {data.spec.name}: performed / planned ratios (1 = as planned)")
    return fig


def block_corners(block: dict[str, float]) -> np.ndarray:
    """``(4, 2)`` corners (m) of a block given by centre ``x, y``, size ``w, h`` and ``angle`` (rad)."""
    c, s = math.cos(block.get("angle", 0.0)), math.sin(block.get("angle", 0.0))
    hw, hh = block["w"] / 2, block["h"] / 2
    local = np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]])
    return local @ np.array([[c, s], [-s, c]]) + [block["x"], block["y"]]


def draw_environment(ax, env: dict[str, Any]) -> None:  # type: ignore[no-untyped-def]
    """Blocks (grey) and the field boundary of an environment file on ``ax``, equal aspect."""
    from matplotlib.patches import Polygon, Rectangle

    w, h = env["size"]
    ax.add_patch(Rectangle((0, 0), w, h, fill=False, lw=1.5, color="0.2"))
    for b in env.get("blocks", []):
        ax.add_patch(Polygon(block_corners(b), closed=True, color="0.55", lw=0))
    ax.set_xlim(-0.03 * w, 1.03 * w)
    ax.set_ylim(-0.03 * h, 1.03 * h)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)


def figure_paths(data: StudyData):  # type: ignore[no-untyped-def]
    """Fig. 8: computed, simulated and field paths over each environment; rows: problems, columns: planners."""
    from matplotlib.figure import Figure

    problems, planners = data.problems, data.planners
    fig = Figure(figsize=(3.1 * len(planners), 3.2 * len(problems) + 0.6), layout="constrained")
    axes = np.asarray(fig.subplots(len(problems), len(planners), squeeze=False))
    by_key = {(e["environment"], e["plan"], e["planner"]): e for e in data.experiments}
    runs = {r["run_id"]: r for r in data.rows}
    for i, (env_name, plan) in enumerate(problems):
        for j, planner in enumerate(planners):
            ax = axes[i, j]
            draw_environment(ax, data.environments[env_name])
            exp = by_key.get((env_name, plan, planner))
            ax.set_title(f"{env_name} {plan} · {planner}", fontsize=9)
            if exp is None:
                continue
            for rid in exp["runs"]:
                r = runs.get(rid)
                if r is None or r.get("status") != "completed":
                    continue
                p = data.poses(rid)
                if len(p):
                    ax.plot(p[:, 1], p[:, 2], color=COLORS[r["mode"]], lw=1.0, alpha=0.8, label=LABELS[r["mode"]])
            if exp.get("planned_path"):
                pp = np.asarray(exp["planned_path"])
                ax.plot(pp[:, 0], pp[:, 1], color="k", ls="--", lw=1.0, label=LABELS["computed"])
            ax.plot(*exp["start"][:2], "o", color="g", ms=5, label="start")
            ax.plot(*exp["goal"][:2], "*", color="g", ms=9, label="goal")
            if exp["status"] not in ("completed",):
                ax.text(0.5, 0.5, exp["status"], transform=ax.transAxes, ha="center", color="r")
    handles = {lab: h for ax in axes.ravel() for h, lab in zip(*ax.get_legend_handles_labels())}
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncols=len(handles), frameon=False)
    fig.suptitle(f"Study {data.spec.name}: computed (dashed), simulated and field paths")
    return fig


def make_figures(data: StudyData) -> dict[str, Any]:
    """``{"fig6_metrics": Figure, "fig7_ratios": Figure, "fig8_paths": Figure}``."""
    return {"fig6_metrics": figure_metrics(data), "fig7_ratios": figure_ratios(data), "fig8_paths": figure_paths(data)}


def save_figures(figures: dict[str, Any], directory: Path, dpi: int = 110) -> list[Path]:
    """Save each figure as ``<name>.png`` and ``<name>.svg`` in ``directory``; returns the paths."""
    out = []
    for name, fig in figures.items():
        for ext in ("png", "svg"):
            path = directory / f"{name}.{ext}"
            fig.savefig(path, dpi=dpi)
            out.append(path)
    return out
