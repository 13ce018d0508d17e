"""Success against difficulty on a generated world set: do BARN's difficulty metrics predict which worlds a
planner fails in?

The unit is the world: each world's success rate (its successful runs of the counted ones, completed or
failed, over the repetitions) for one configuration and mode, against each of the world's difficulty metrics
(``planners.worlds.Difficulty``, stored with the study's ``worlds``); Spearman's rank correlation over the
worlds (``scipy.stats.spearmanr``: ties averaged, its two-sided p-value): BARN's question of whether its metrics
order worlds by how hard they are to navigate, asked of this study's planners.  A correlation is not given where fewer than three worlds have counted runs or the
success rate (or the metric) is the same in every world: there is nothing to rank.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
from scipy.stats import spearmanr

from contract.vocabulary import JUDGED

from ._data import StudyData

__all__ = ["DIFFICULTY_METRICS", "DifficultyCorrelation", "difficulty_correlations", "difficulty_table",
           "figure_difficulty", "world_success"]

#: the difficulty metrics (``planners.worlds.Difficulty``) and how tables and figures name them
DIFFICULTY_METRICS = {"distance_to_obstacle_m": "distance to obstacle (m)", "visibility_m": "visibility (m)",
                      "dispersion": "dispersion", "characteristic_dimension_m": "characteristic dimension (m)",
                      "tortuosity": "tortuosity"}


@dataclass(frozen=True)
class DifficultyCorrelation:
    """Spearman's rho of one configuration's per-world success rate in one mode against one difficulty metric,
    over ``worlds`` worlds (``runs`` counted runs); ``rho``/``p`` None with ``note`` where there is nothing to
    rank."""

    configuration: str
    mode: str
    metric: str
    rho: Optional[float]
    p: Optional[float]
    worlds: int
    runs: int
    note: str = ""

    def row(self) -> dict[str, Any]:
        return {"configuration": self.configuration, "mode": self.mode, "metric": self.metric, "rho": self.rho,
                "p": self.p, "worlds": self.worlds, "runs": self.runs, "note": self.note}


def world_success(data: StudyData) -> dict[tuple[str, str], dict[str, tuple[int, int]]]:
    """``(configuration, mode) -> {world: (successes, counted runs)}`` over the study's worlds."""
    worlds = (data.spec.worlds or {}).get("worlds", {})
    out: dict[tuple[str, str], dict[str, tuple[int, int]]] = {}
    for r in data.rows:
        if r.get("environment") not in worlds or r.get("status") not in JUDGED:
            continue
        cell = out.setdefault((r["configuration"], r["mode"]), {})
        won, n = cell.get(r["environment"], (0, 0))
        cell[r["environment"]] = (won + (r.get("outcome") == "success"), n + 1)
    return out


def difficulty_correlations(data: StudyData) -> list[DifficultyCorrelation]:
    """Every configuration x mode x difficulty metric (:mod:`module docstring <._worlds>`); empty without a
    world set."""
    worlds = (data.spec.worlds or {}).get("worlds", {})
    out = []
    for (config, mode), cell in sorted(world_success(data).items()):
        names = sorted(cell)
        rate = np.array([cell[w][0] / cell[w][1] for w in names])
        runs = sum(n for _, n in cell.values())
        for metric in DIFFICULTY_METRICS:
            x = np.array([worlds[w]["difficulty"].get(metric, math.nan) for w in names], dtype=float)
            ok = np.isfinite(x)
            note = ""
            if ok.sum() < 3:
                note = "fewer than 3 worlds counted"
            elif np.ptp(rate[ok]) == 0:
                note = f"success {rate[ok][0]:.0%} in every world"
            elif np.ptp(x[ok]) == 0:
                note = "metric equal in every world"
            if note:
                out.append(DifficultyCorrelation(config, mode, metric, None, None, int(ok.sum()), runs, note))
                continue
            res = spearmanr(x[ok], rate[ok])
            out.append(DifficultyCorrelation(config, mode, metric, float(res.statistic), float(res.pvalue),
                                             int(ok.sum()), runs))
    return out


def difficulty_table(data: StudyData) -> Optional[tuple[str, list[str], list[list[str]]]]:
    """The report's table: rho (p) per configuration x mode (rows) and metric (columns); None without worlds."""
    if not data.spec.worlds:
        return None
    cors = difficulty_correlations(data)
    if not cors:
        return None
    by = {(c.configuration, c.mode, c.metric): c for c in cors}
    success = world_success(data)
    body = []
    for config, mode in dict.fromkeys((c.configuration, c.mode) for c in cors):
        mine = [by[(config, mode, m)] for m in DIFFICULTY_METRICS]
        rates = [won / n for won, n in success[(config, mode)].values()]
        cells = ["–" if c.rho is None else f"{c.rho:+.2f} (p {c.p:.2g})" for c in mine]
        notes = "; ".join(dict.fromkeys(c.note for c in mine if c.note))
        body.append([config, mode, f"{mine[0].worlds} / {mine[0].runs}", f"{np.mean(rates):.0%}", *cells, notes])
    ws = data.spec.worlds
    title = (f"Success against difficulty: Spearman's rho of each world's success rate with its difficulty metric "
             f"(p two-sided), over the worlds of {ws['index']} (split {ws['split']}, {len(ws['worlds'])} worlds); "
             "negative: harder by that measure, fewer successes")
    return title, ["configuration", "mode", "worlds / runs", "mean success", *DIFFICULTY_METRICS.values(), "note"], body


def figure_difficulty(data: StudyData) -> Any:
    """Each world's success rate against each difficulty metric, a panel per metric, a series per configuration
    and mode (field filled, simulation hollow), rho in the legend."""
    from matplotlib.figure import Figure

    worlds = (data.spec.worlds or {}).get("worlds", {})
    success = world_success(data)
    rho = {(c.configuration, c.mode, c.metric): c for c in difficulty_correlations(data)}
    fig = Figure(figsize=(3.1 * len(DIFFICULTY_METRICS), 3.4), layout="constrained")
    axes = fig.subplots(1, len(DIFFICULTY_METRICS), sharey=True)
    colors = {c: f"C{i % 10}" for i, c in enumerate(dict.fromkeys(k[0] for k in success))}
    for ax, (metric, label) in zip(axes, DIFFICULTY_METRICS.items()):
        for (config, mode), cell in success.items():
            names = sorted(cell)
            x = [worlds[w]["difficulty"].get(metric, math.nan) for w in names]
            y = [cell[w][0] / cell[w][1] for w in names]
            c = rho[(config, mode, metric)]
            tag = "n/a" if c.rho is None else f"{c.rho:+.2f}"
            ax.scatter(x, y, s=22, color=colors[config], facecolors=colors[config] if mode == "twb" else "none",
                       label=f"{config} {mode} (ρ {tag})", alpha=0.8)
        ax.set_xlabel(label)
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6, loc="lower left")
    axes[0].set_ylabel("success rate per world")
    ws = data.spec.worlds or {}
    fig.suptitle(f"Success against difficulty ({len(worlds)} worlds, split {ws.get('split', 'all')})", fontsize=10)
    return fig
