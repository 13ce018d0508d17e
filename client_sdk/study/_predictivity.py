"""Sim-to-field predictivity: where the simulation predicts the field and where it does not.

After Habitat's sim-to-real predictivity (Kadian et al., *Sim2Real Predictivity:
Does Evaluation in Simulation Predict Real-World Performance?*, RA-L 2020: the
Sim-vs-Real Correlation Coefficient, SRCC), for each metric of a study with both
modes and several configurations (planners, or planner x controller pairs):

- **Spearman ρ** between the configurations' simulated and field results across
  problems: one point per configuration and problem (environment, plan), its
  mean over the repetitions in simulation (x) and on the field (y), ranked
  (:func:`scipy.stats.spearmanr`).  ρ near 1: ranking configurations and problems
  by the simulation ranks them as the field would.
- **ρ within problems**: the same per problem over its configurations, averaged
  over the problems (the ranking of configurations on one problem).
- **flipped**: the share of the pairs of configurations on the same problem whose
  order by the metric reverses between simulation and field (a pair tied in either
  mode is not counted).  0: the simulation never misorders two configurations;
  0.5: a coin would do as well.

A pure function of a :class:`~client_sdk.study.StudyData`; ``twb study`` writes
``predictivity.md``, ``predictivity.json`` and ``predictivity.png``
(docs/fidelity.md, "Predictivity").
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._data import StudyData

__all__ = ["PREDICTIVITY_METRICS", "MetricPredictivity", "predictivity", "predictivity_json",
           "predictivity_markdown", "write_predictivity"]

#: metric -> its name in tables: the paper's Fig. 6 and 7 metrics
PREDICTIVITY_METRICS: dict[str, str] = {
    "execution_time_s": "execution time (s)",
    "average_speed_m_s": "average speed (m/s)",
    "length_m": "path length (m)",
    "length_ratio": "length ratio",
    "deviation_mean_m": "mean deviation (m)",
    "deviation_max_m": "maximum deviation (m)",
    "clearance_min_m": "minimum clearance (m)",
    "smoothness_rad": "smoothness κ' (rad)",
}


@dataclass(frozen=True)
class MetricPredictivity:
    """How well the simulation predicts the field for one metric (None: not enough data)."""

    metric: str
    spearman: float | None  #: ρ over (configuration, problem) cells
    spearman_within: float | None  #: mean over problems of ρ over the configurations
    flipped: float | None  #: share of the configuration pairs on a problem whose order flips
    pairs: int  #: pairs counted for ``flipped``
    cells: int  #: (configuration, problem) cells with both modes
    configurations: int
    problems: int

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _cells(data: StudyData, metric: str) -> dict[tuple[str, str], dict[str, tuple[float, float]]]:
    """problem -> configuration -> (mean simulated, mean field) of ``metric`` over the completed runs."""
    acc: dict[tuple[str, str, str, str], list[float]] = {}
    for r in data.rows:
        v = r.get(metric)
        if r.get("status") != "completed" or r.get("mode") not in ("sim", "twb") or isinstance(v, bool) \
                or not isinstance(v, (int, float)) or not math.isfinite(v):
            continue
        conf = str(r.get("configuration") or r["planner"])
        if r.get("profile"):
            conf = f"{conf} · {r['profile']}"
        acc.setdefault((r["environment"], r["plan"], conf, r["mode"]), []).append(float(v))
    out: dict[tuple[str, str], dict[str, tuple[float, float]]] = {}
    for (env, plan, conf, mode), vals in acc.items():
        if mode != "sim" or (env, plan, conf, "twb") not in acc:
            continue
        out.setdefault((env, plan), {})[conf] = (float(np.mean(vals)), float(np.mean(acc[(env, plan, conf, "twb")])))
    return out


def _spearman(x: list[float], y: list[float]) -> float | None:
    from scipy.stats import spearmanr

    if len(x) < 3 or len(set(x)) < 2 or len(set(y)) < 2:
        return None
    rho = float(spearmanr(x, y).statistic)
    return rho if math.isfinite(rho) else None


def _one(data: StudyData, metric: str) -> MetricPredictivity:
    cells = _cells(data, metric)
    xs = [sv for confs in cells.values() for sv, _ in confs.values()]
    ys = [fv for confs in cells.values() for _, fv in confs.values()]
    within, flips, pairs = [], 0, 0
    for confs in cells.values():
        vals = list(confs.values())
        rho = _spearman([v[0] for v in vals], [v[1] for v in vals])
        if rho is not None:
            within.append(rho)
        for (sa, fa), (sb, fb) in itertools.combinations(vals, 2):
            ds, df = np.sign(sa - sb), np.sign(fa - fb)
            if ds == 0 or df == 0:
                continue
            pairs += 1
            flips += int(ds != df)
    confs_all = {c for confs in cells.values() for c in confs}
    return MetricPredictivity(metric, _spearman(xs, ys), float(np.mean(within)) if within else None,
                              flips / pairs if pairs else None, pairs, len(xs), len(confs_all), len(cells))


def predictivity(data: StudyData, metrics: list[str] | None = None) -> list[MetricPredictivity]:
    """The predictivity of every metric (default :data:`PREDICTIVITY_METRICS`) on ``data``'s completed runs of
    both modes; a metric without two configurations on a problem in both modes has None values."""
    return [_one(data, m) for m in (metrics or list(PREDICTIVITY_METRICS))]


def _f(x: float | None, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def predictivity_markdown(found: list[MetricPredictivity]) -> str:
    """The predictivity as a Markdown table."""
    n = max((p.configurations for p in found), default=0)
    q = max((p.problems for p in found), default=0)
    lines = ["# Sim-to-field predictivity", "",
             (f"{n} configurations on {q} problems. Spearman ρ between the simulated and the field means of each "
             "configuration and problem (across problems, and within a problem averaged over the problems); "
             "flipped: the share of configuration pairs on a problem whose order reverses from simulation to "
             "field (docs/fidelity.md, \"Predictivity\")."), "",
             "| metric | Spearman ρ | ρ within problems | flipped | pairs |", "|---|---|---|---|---|"]
    for p in found:
        lines.append(f"| {PREDICTIVITY_METRICS.get(p.metric, p.metric)} | {_f(p.spearman)} | "
                     f"{_f(p.spearman_within)} | {_f(p.flipped)} | {p.pairs} |")
    return "\n".join(lines) + "\n"


def predictivity_json(found: list[MetricPredictivity]) -> dict[str, Any]:
    return {"metrics": [p.to_json() for p in found]}


def figure_predictivity(found: list[MetricPredictivity]):  # type: ignore[no-untyped-def]
    """Bars per metric: Spearman ρ across problems, ρ within problems and the flipped share."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4), layout="constrained")
    ax = fig.add_subplot()
    x = np.arange(len(found))
    w = 0.27
    for j, (label, key, color) in enumerate((("Spearman ρ across problems", "spearman", "tab:blue"),
                                             ("ρ within problems", "spearman_within", "tab:cyan"),
                                             ("share of orderings flipped", "flipped", "tab:red"))):
        vals = [getattr(p, key) for p in found]
        ax.bar(x + (j - 1) * w, [np.nan if v is None else v for v in vals], w, label=label, color=color)
    ax.axhline(0, color="black", lw=0.6)
    ax.axhline(0.5, color="tab:red", lw=0.6, ls=":")
    ax.set_xticks(x, [PREDICTIVITY_METRICS.get(p.metric, p.metric) for p in found], rotation=25, ha="right",
                  fontsize=8)
    ax.set_ylim(-1, 1)
    n = max((p.configurations for p in found), default=0)
    ax.set_title(f"Does the simulation predict the field? {n} configurations", fontsize=10)
    ax.legend(fontsize=8, loc="lower left")
    return fig


def write_predictivity(data: StudyData, directory: Path | None = None) -> list[MetricPredictivity] | None:
    """Write ``predictivity.md``, ``.json`` and ``.png`` into ``directory`` (default: the study's) when the study
    has two configurations with runs in both modes on a problem; returns the predictivity, else None."""
    if data.spec.fleet:
        return None
    found = predictivity(data)
    if not any(p.pairs for p in found):
        return None
    d = Path(directory or data.directory or ".")
    d.mkdir(parents=True, exist_ok=True)
    (d / "predictivity.md").write_text(predictivity_markdown(found))
    (d / "predictivity.json").write_text(json.dumps(predictivity_json(found), indent=1, ensure_ascii=False) + "\n")
    figure_predictivity(found).savefig(d / "predictivity.png", dpi=110)
    return found
