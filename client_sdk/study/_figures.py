"""The study's figures, after the paper's Fig. 6, 7 and 8, and the outcomes, as matplotlib ``Figure`` objects.

Failures are results here too: the outcomes figure shows how every
configuration's runs ended; Fig. 6 and 7 say under each group over how many
runs a bar is and write "no completed run" where a mode has none (instead of
dropping the bar); Fig. 8 draws failed runs up to where they stopped, with a ✕.

Built with ``matplotlib.figure.Figure`` (no pyplot, no global state, any
backend), from a :class:`~client_sdk.study.StudyData` only, so they can be
redrawn offline from a study directory.  Saving is the caller's business
(:func:`save_figures`).
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any, Iterable, Optional

import numpy as np

from contract.vocabulary import JUDGED, Mode

from ._data import StudyData
from ._obstacle_paths import draw_obstacles
from ._verdict import MODE_WORDS, display_name

__all__ = ["FIG6_METRICS", "FIG7_RATIOS", "MAX_PATH_ROWS", "OUTCOME_COLORS", "figure_metrics", "figure_outcomes", "figure_paths",
           "figure_ratios", "mean_std", "save_figures"]

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
COLORS = {"computed": "#7f7f7f", "sim": "#1f77b4", "twb": "#d62728", "direct": "#9467bd", "failed": "#ff7f0e"}
LABELS = {"computed": "computed (planned)", "sim": "simulation (S)", "twb": "Teleworkbench (T)",
          "direct": "direct comparison (ST)", "failed": "failed run (✕ where it stopped)"}
SHORT = {"sim": "S", "twb": "T"}
#: segments of the outcomes figure
OUTCOME_COLORS = {"success": "#2ca02c", "collision": "#ff7f0e", "timeout": "#9467bd", "other": "#8c564b",
                  # a fleet's runs, by kind (client_sdk.study._fleet_results.FLEET_KINDS)
                  "robot-robot collision": "#ff7f0e", "moving-obstacle collision": "#d62728",
                  "block/wall collision": "#e377c2", "deadlock": "#17becf"}


def legend_and_title(fig, handles: dict[str, Any], title: str, **legend_kw: Any) -> None:  # type: ignore[no-untyped-def]
    """The figure's legend below it, in as many columns as fit its width, and its title, wrapped to its width
    (a legend of one row or a long study name no longer runs off a narrow figure)."""
    width = 0.98 * fig.get_figwidth() * fig.dpi
    ncols = max(len(handles), 1)
    while True:
        legend = fig.legend(list(handles.values()), list(handles.keys()), loc="outside lower center", ncols=ncols,
                            frameon=False, **legend_kw)
        if ncols == 1 or legend.get_window_extent().width <= width:
            break
        legend.remove()
        ncols -= 1
    chars = len(title)
    while True:
        text = textwrap.fill(title, chars, break_on_hyphens=False)
        suptitle = fig.suptitle(text)
        if chars <= 20 or suptitle.get_window_extent().width <= width:
            break
        chars = int(chars * 0.9)


def mean_std(values: Iterable[Any]) -> tuple[Optional[float], Optional[float], int]:
    """Mean, sample std (ddof 1; None below 2 values) and count of the finite numbers in ``values``."""
    xs = np.array([float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)
                   and math.isfinite(float(v))])
    if xs.size == 0:
        return None, None, 0
    return float(xs.mean()), (float(xs.std(ddof=1)) if xs.size > 1 else None), int(xs.size)


def _completed(data: StudyData) -> list[dict[str, Any]]:
    return [r for r in data.rows if r.get("status") == "completed"]


def _tick_label(data: StudyData, config: str, modes: Iterable[str]) -> str:
    """``FM²`` (a field-robot variant on a line of its own: ``FMM\ntracker 3 mm``) and, per mode, completed of
    runs: ``S 2/2 · T 0/2``; with more than three configurations a line per mode, so that neighbours' labels
    do not run into each other.  Dollar signs are escaped (no mathtext)."""
    counts = []
    for m in modes:
        mine = [r for r in data.rows if r["configuration"] == config and r["mode"] == m]
        counts.append(f"{SHORT.get(m, m)} {sum(r.get('status') == 'completed' for r in mine)}/{len(mine)}")
    sep = "\n" if len(data.configurations) > 3 else " · "
    return (display_name(config).replace(" · ", "\n", 1) + "\n" + sep.join(counts)).replace("$", r"\$")


def _grouped_bars(ax, labels: list[str], series: dict[str, list[tuple[Optional[float], Optional[float]]]],  # type: ignore[no-untyped-def]
                  missing: Optional[dict[str, list[bool]]] = None) -> None:
    """Bars per kind and group; where ``missing`` flags a group without completed runs, say so instead of a bar."""
    missing = missing or {}
    kinds = [k for k, vals in series.items() if any(m is not None for m, _ in vals) or any(missing.get(k, []))]
    width = 0.8 / max(len(kinds), 1)
    x = np.arange(len(labels))
    for i, kind in enumerate(kinds):
        means = [m if m is not None else np.nan for m, _ in series[kind]]
        errs = [s if s is not None else 0.0 for _, s in series[kind]]
        pos = x + (i - (len(kinds) - 1) / 2) * width
        ax.bar(pos, means, width, yerr=errs, capsize=2, color=COLORS[kind], label=LABELS[kind])
        for xp, gone in zip(pos, missing.get(kind, [])):
            if gone:
                ax.text(xp, 0.02, "no completed run", transform=ax.get_xaxis_transform(), rotation=90, ha="center",
                        va="bottom", fontsize=7, color=COLORS[kind])
    ax.set_xticks(x, labels, fontsize=8 if len(labels) <= 3 else 7)
    ax.grid(axis="y", color="0.9")
    ax.set_axisbelow(True)


def _missing(data: StudyData, configs: list[str], modes: Iterable[str]) -> dict[str, list[bool]]:
    """Per mode and configuration: runs exist but none completed."""
    out = {}
    for m in modes:
        out[m] = [bool([r for r in data.rows if r["configuration"] == c and r["mode"] == m])
                  and not [r for r in data.rows if r["configuration"] == c and r["mode"] == m
                           and r.get("status") == "completed"] for c in configs]
    return out


def figure_metrics(data: StudyData):  # type: ignore[no-untyped-def]
    """Fig. 6: each metric per planner: computed path, simulation, Teleworkbench, and the direct comparison.

    One panel per :data:`FIG6_METRICS`; bars are means over the completed runs
    of all environments and plans, error bars one standard deviation; under
    each group the completed runs of all runs per mode, and "no completed run"
    where a mode has none.
    """
    from matplotlib.figure import Figure

    rows, planners = _completed(data), data.configurations
    labels = [_tick_label(data, p, data.modes) for p in planners]
    missing = _missing(data, planners, data.modes)
    fig = Figure(figsize=(12, 6.5), layout="constrained")
    axes = fig.subplots(2, 3).ravel()
    for ax, (key, label) in zip(axes, FIG6_METRICS):
        series: dict[str, list] = {k: [] for k in ("computed", "sim", "twb", "direct")}
        for p in planners:
            mine = [r for r in rows if r["configuration"] == p]
            planned = {(r["experiment_id"]): r.get(f"planned_{key}") for r in mine}
            series["computed"].append(mean_std(planned.values())[:2] if f"planned_{key}" in _keys(mine) else (None, None))
            for mode in (Mode.SIM, Mode.TWB):
                series[mode].append(mean_std(r.get(key) for r in mine if r["mode"] == mode)[:2])
            series["direct"].append(mean_std(d.get(key) for d in data.direct if d["configuration"] == p)[:2]
                                    if key == "deviation_mean_m" else (None, None))
        _grouped_bars(ax, labels, series, missing)
        ax.set_title(label)
    handles = {lab: h for ax in axes for h, lab in zip(*ax.get_legend_handles_labels())}
    legend_and_title(fig, handles, f"Study {data.spec.name}: metrics per configuration (mean ± std over the completed "
                     f"runs: {len(rows)} of {len(data.rows)})")
    return fig


def _keys(rows: list[dict[str, Any]]) -> set[str]:
    return {k for r in rows for k, v in r.items() if v is not None}


def figure_ratios(data: StudyData):  # type: ignore[no-untyped-def]
    """Fig. 7: performed / planned ratios (length, smoothness, clearance) per planner, sim and twb."""
    from matplotlib.figure import Figure

    rows, planners = _completed(data), data.configurations
    labels = [_tick_label(data, p, data.modes) for p in planners]
    missing = _missing(data, planners, data.modes)
    fig = Figure(figsize=(12, 4.0), layout="constrained")
    axes = fig.subplots(1, len(FIG7_RATIOS))
    for ax, (key, label) in zip(axes, FIG7_RATIOS):
        series = {mode: [mean_std(r.get(key) for r in rows if r["configuration"] == p and r["mode"] == mode)[:2]
                         for p in planners] for mode in (Mode.SIM, Mode.TWB)}
        _grouped_bars(ax, labels, series, missing)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_title(f"{label} (performed / planned)")
    handles = {lab: h for ax in axes for h, lab in zip(*ax.get_legend_handles_labels())}
    legend_and_title(fig, handles, f"Study {data.spec.name}: performed / planned ratios over the completed runs "
                     "(1 = as planned)")
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


#: Fig. 8 draws at most this many problems (rows); a larger study says so in the title (every path is in poses/)
MAX_PATH_ROWS = 12


def figure_paths(data: StudyData, *, max_rows: int = MAX_PATH_ROWS):  # type: ignore[no-untyped-def]
    """Fig. 8: computed, simulated and field paths over each environment, with its moving obstacles' exact tracks
    over the panel's longest run; rows: problems (the first ``max_rows``), columns: configurations.  Each panel's
    runs are drawn as one collection per kind."""
    from matplotlib.figure import Figure

    problems, planners = data.problems, data.configurations
    shown = problems[:max_rows]
    fig = Figure(figsize=(3.1 * len(planners), 3.2 * len(shown) + 0.6), layout="constrained")
    axes = np.asarray(fig.subplots(len(shown), len(planners), squeeze=False))
    by_key = {(e["environment"], e["plan"], e["configuration"]): e for e in data.experiments}
    runs = {r["run_id"]: r for r in data.rows}
    for i, (env_name, plan) in enumerate(shown):
        for j, planner in enumerate(planners):
            ax = axes[i, j]
            draw_environment(ax, data.environments[env_name])
            exp = by_key.get((env_name, plan, planner))
            ax.set_title(f"{env_name} {plan} · {planner}", fontsize=9)
            if exp is None:
                continue
            drawn = [runs[rid] for rid in exp["runs"] if rid in runs and runs[rid].get("status") in JUDGED]
            draw_obstacles(ax, data.environments[env_name], _longest(drawn), None)
            _draw_runs(ax, data, drawn)
            plans = list((exp.get("repetition_paths") or {}).values()) or \
                ([exp["planned_path"]] if exp.get("planned_path") else [])
            for pp in map(np.asarray, plans):  # a randomised planner's: every repetition's own
                ax.plot(pp[:, 0], pp[:, 1], color="k", ls="--", lw=1.0 if len(plans) == 1 else 0.8,
                        label=LABELS["computed"])
            ax.plot(*exp["start"][:2], "o", color="g", ms=5, label="start")
            ax.plot(*exp["goal"][:2], "*", color="g", ms=9, label="goal")
            _outcome_note(ax, exp, runs)
    handles = {lab: h for ax in axes.ravel() for h, lab in zip(*ax.get_legend_handles_labels())}
    more = f" (the first {len(shown)} of {len(problems)} problems; every path is in poses/)" \
        if len(shown) < len(problems) else ""
    legend_and_title(fig, handles, f"Study {data.spec.name}: computed (dashed), simulated and field paths{more}")
    return fig


def _longest(rows: list[dict[str, Any]]) -> float:
    """The longest of the runs' drives (s, ``t_end - t_start``; 0 without one)."""
    spans = [r["t_end"] - r["t_start"] for r in rows
             if isinstance(r.get("t_start"), (int, float)) and isinstance(r.get("t_end"), (int, float))]
    return max(spans, default=0.0)


def _draw_runs(ax, data: StudyData, rows: list[dict[str, Any]]) -> None:  # type: ignore[no-untyped-def]
    """Runs' driven paths: completed in their mode's colour; failed in orange, up to where they stopped, with
    a ✕ (one line collection per kind: a panel of hundreds of runs stays one artist each)."""
    from matplotlib.collections import LineCollection

    lines: dict[str, list[np.ndarray]] = {}
    crosses = []
    for r in rows:
        p = data.poses(r["run_id"])
        kind = r["mode"] if r.get("status") == "completed" else "failed"
        if len(p):
            lines.setdefault(kind, []).append(p[:, 1:3])
        if kind != "failed":
            continue
        x, y = r.get("stopped_at_x"), r.get("stopped_at_y")
        if not (isinstance(x, (int, float)) and isinstance(y, (int, float))) and len(p):
            x, y = p[-1, 1], p[-1, 2]
        if isinstance(x, (int, float)) and isinstance(y, (int, float)):
            crosses.append((x, y))
    for kind, segs in lines.items():
        failed = kind == "failed"
        ax.add_collection(LineCollection(segs, colors=COLORS[kind], linewidths=1.4 if failed else 1.0,
                                         alpha=1.0 if failed else 0.8, label=LABELS[kind]))
    if crosses:
        xs, ys = zip(*crosses)
        ax.plot(xs, ys, marker="x", ms=9, mew=2.4, color=COLORS["failed"], ls="none", label=LABELS["failed"])


def _outcome_note(ax, exp: dict[str, Any], runs: dict[int, dict[str, Any]]) -> None:  # type: ignore[no-untyped-def]
    """What did not succeed, per mode, in the panel's corner (``T: collision 5/5``); a refused job in the middle."""
    if exp["status"] == "rejected":
        ax.text(0.5, 0.5, "refused by the testbed", transform=ax.transAxes, ha="center", color=COLORS["failed"],
                fontsize=8)
        return
    lines = []
    for mode in dict.fromkeys(runs[rid]["mode"] for rid in exp["runs"] if rid in runs):
        mine = [runs[rid] for rid in exp["runs"] if rid in runs and runs[rid]["mode"] == mode]
        bad: dict[str, int] = {}
        for r in mine:
            if r.get("outcome") != "success":
                bad[r.get("outcome") or r.get("status")] = bad.get(r.get("outcome") or r.get("status"), 0) + 1
        if bad:
            lines.append(f"{SHORT.get(mode, mode)}: " + ", ".join(f"{o} {n}/{len(mine)}" for o, n in bad.items()))
    if lines:
        ax.text(0.02, 0.98, "\n".join(lines), transform=ax.transAxes, ha="left", va="top", fontsize=7,
                color="0.15", bbox={"facecolor": "white", "alpha": 0.8, "lw": 0, "pad": 1.5})


def figure_outcomes(data: StudyData, outcomes: Optional[list[Any]] = None):  # type: ignore[no-untyped-def]
    """How the runs ended: one bar per configuration and mode, split into success, collision, timeout and other
    failures (``outcomes``' named columns: a fleet study's by kind) as fractions of the counted runs, with the
    success rate's Wilson 95% interval as a whisker."""
    from matplotlib.figure import Figure

    outcomes = outcomes if outcomes is not None else data.outcomes()
    fig = Figure(figsize=(9, 0.55 * len(outcomes) + 1.6), layout="constrained")
    ax = fig.subplots()
    labels = []
    for i, o in enumerate(outcomes):
        y = len(outcomes) - 1 - i
        labels.append(f"{display_name(o.configuration)} · {MODE_WORDS.get(o.mode, o.mode).split(' (')[0].lower()}")
        left = 0.0
        n = o.counted
        for col in (*o.NAMED, "other"):
            k = o.count(col)
            if n and k:
                ax.barh(y, k / n, left=left, color=OUTCOME_COLORS[col], height=0.6, label=col)
                left += k / n
        s = o.success
        if s.get("rate") is not None:
            ax.errorbar(s["rate"], y, xerr=[[s["rate"] - s["ci_low"]], [s["ci_high"] - s["rate"]]], fmt="none",
                        ecolor="k", capsize=3, lw=1)
        text = f"{o.successes}/{n} succeeded" if n else "no counted run"
        if o.not_counted:
            text += f"; {o.not_counted} not counted"
        if o.identical:
            text += " (identical repetitions)"
        ax.text(1.02, y, text, va="center", fontsize=8)
    ax.set_yticks(range(len(outcomes)), labels[::-1], fontsize=8)
    ax.set_xlim(0, 1.45)
    ax.set_xticks([0, 0.25, 0.5, 0.75, 1.0])
    ax.set_xlabel("fraction of the counted runs (completed or failed); whisker: success rate, Wilson 95% interval")
    handles = {lab: h for h, lab in zip(*ax.get_legend_handles_labels())}
    ax.grid(axis="x", color="0.9")
    ax.set_axisbelow(True)
    legend_and_title(fig, handles, f"Study {data.spec.name}: outcomes per configuration and mode", fontsize=8)
    return fig


def save_figures(figures: dict[str, Any], directory: Path, dpi: int = 110) -> list[Path]:
    """Save each figure as ``<name>.png`` and ``<name>.svg`` in ``directory``; returns the paths."""
    out = []
    for name, fig in figures.items():
        for ext in ("png", "svg"):
            path = directory / f"{name}.{ext}"
            fig.savefig(path, dpi=dpi)
            out.append(path)
    return out
