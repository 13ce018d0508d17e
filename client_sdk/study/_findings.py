"""The paper's qualitative findings, checked on a study's data.

Tanoto et al. (*Teletesting*, §IV, Fig. 6 and 7) compare the paths FMM, FM² and
PRM compute with what a simulated robot (S) and the Teleworkbench's real robots
(T) drove.  :func:`paper_findings` turns their claims into nine checks, each a
comparison of per-planner means over the study's completed runs (the bars of
Fig. 6 and 7) with a stated threshold, and returns each with the numbers behind
it and whether it held.  It is a pure function of a
:class:`~client_sdk.study.StudyData`: the study directory of ``twb study`` is
enough, offline.  docs/fidelity.md explains each check and the mechanism of the
emulated field that makes it hold.

A check needs the planners and modes it speaks of; without them it is *not
applicable* (``held`` is None), never passed by default.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

from ._data import StudyData
from ._figures import mean_std

__all__ = ["FINDINGS", "Finding", "findings_json", "findings_markdown", "paper_findings", "write_findings"]

#: thresholds of the checks (see docs/fidelity.md)
SIM_LENGTH_TOLERANCE = 0.03  #: |S length ratio − 1| at most this: the simulated robot drives the planned length
SIM_DEVIATION_MAX_M = 0.01  #: S mean deviation below this (m): the simulated robot stays on the path
SIMILAR_LENGTH_RATIO = 0.05  #: |T length ratio − S length ratio| at most this: "similar" length deviation


@dataclass(frozen=True)
class Finding:
    """One of the paper's claims, checked: ``held`` is True, False or None (not applicable)."""

    key: str
    claim: str  #: the paper's claim, in its words where it has them
    check: str  #: how it is checked: metric, comparison, threshold
    held: Optional[bool]
    numbers: dict[str, Any] = field(default_factory=dict)  #: the means behind the verdict
    detail: str = ""  #: the comparison with the numbers, one line

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


#: (key, claim, check) of the nine findings, in the order they are reported
FINDINGS: tuple[tuple[str, str, str], ...] = (
    ("fmm_shortest", "FMM computes the shortest paths.",
     "computed paths: mean length of FMM ≤ mean length of FM² and of PRM"),
    ("fm2_safest", "FM² computes the safest paths: the largest clearance.",
     "computed paths: mean minimum clearance of FM² > that of FMM and of PRM"),
    ("prm_sharpest", "PRM's paths are characterised by sharp curves: the least smooth.",
     "computed paths: mean κ' of PRM > mean κ' of FMM and of FM²"),
    ("sim_follows_plan", "In simulation the robot drives the computed path almost exactly.",
     f"every planner: |S length ratio − 1| ≤ {SIM_LENGTH_TOLERANCE:g} and S mean deviation "
     f"< {SIM_DEVIATION_MAX_M * 1000:g} mm"),
    ("field_slower", "Real runs take longer than simulated ones.",
     "every planner: mean execution time T > S"),
    ("field_deviates_more", "The real robot deviates more from the computed path than the simulated one.",
     "every planner: mean deviation T > S"),
    ("length_similar", "Path length deviation shows similar results in simulation and in real experiments.",
     f"every planner: |T length ratio − S length ratio| ≤ {SIMILAR_LENGTH_RATIO:g}"),
    ("prm_smoother_on_field", "The smoothness of PRM is improved on the real robot: the controller cannot "
     "follow the sharp curves a PRM path is characterised by.",
     "PRM's T smoothness ratio < 1 and < S smoothness ratio, and the lowest T smoothness ratio of all planners"),
    ("field_less_clearance", "The real robot keeps less clearance than the simulated one.",
     "every planner: mean minimum clearance T < S"),
)


def _mean(rows: list[dict[str, Any]], key: str) -> Optional[float]:
    return mean_std(r.get(key) for r in rows)[0]


def _r(x: Optional[float], digits: int = 4) -> Optional[float]:
    return None if x is None else round(x, digits)


def _fmt(x: Optional[float], digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def paper_findings(data: StudyData) -> list[Finding]:
    """The nine findings (:data:`FINDINGS`) on ``data``'s completed runs, in that order.

    Means are per planner (and mode) over the completed runs; computed-path
    means are over the planner's experiments (each counted once).
    """
    done = [r for r in data.rows if r.get("status") == "completed"]
    planners = list(dict.fromkeys(r["planner"] for r in done))

    def runs(p: str, mode: str) -> list[dict[str, Any]]:
        return [r for r in done if r["planner"] == p and r["mode"] == mode]

    def planned(p: str, key: str) -> Optional[float]:
        per_exp = {r["experiment_id"]: r.get(f"planned_{key}") for r in done if r["planner"] == p}
        return mean_std(per_exp.values())[0]

    def mode_mean(p: str, mode: str, key: str) -> Optional[float]:
        return _mean(runs(p, mode), key)

    out: list[Finding] = []
    spec = {k: (claim, check) for k, claim, check in FINDINGS}

    def add(key: str, held: Optional[bool], numbers: dict[str, Any], detail: str) -> None:
        claim, check = spec[key]
        out.append(Finding(key, claim, check, held, numbers, detail))

    # 1-3: computed paths
    for key, metric, best, sign in (("fmm_shortest", "length_m", "fmm", -1), ("fm2_safest", "clearance_min_m", "fm2", 1),
                                    ("prm_sharpest", "smoothness_rad", "prm", 1)):
        vals = {p: planned(p, metric) for p in ("fmm", "fm2", "prm")}
        numbers = {f"{p}_planned_{metric}": _r(v) for p, v in vals.items()}
        if any(v is None for v in vals.values()):
            add(key, None, numbers, "needs computed paths of FMM, FM² and PRM")
            continue
        others = [v for p, v in vals.items() if p != best]
        held = all(vals[best] <= o for o in others) if sign < 0 else all(vals[best] > o for o in others)
        rel = "≤" if sign < 0 else ">"
        add(key, held, numbers, f"{best}: {_fmt(vals[best])} {rel} " +
            ", ".join(f"{p} {_fmt(v)}" for p, v in vals.items() if p != best) + f" ({metric})")

    both = [p for p in planners if runs(p, "sim") and runs(p, "twb")]

    # 4: simulation follows the plan
    sim_planners = [p for p in planners if runs(p, "sim")]
    numbers = {}
    held: Optional[bool] = None
    parts = []
    if sim_planners:
        held = True
        for p in sim_planners:
            lr, dev = mode_mean(p, "sim", "length_ratio"), mode_mean(p, "sim", "deviation_mean_m")
            numbers[f"{p}_sim_length_ratio"], numbers[f"{p}_sim_deviation_mean_m"] = _r(lr), _r(dev, 5)
            ok = lr is not None and dev is not None and abs(lr - 1) <= SIM_LENGTH_TOLERANCE and dev < SIM_DEVIATION_MAX_M
            held = held and ok
            parts.append(f"{p} {_fmt(lr)} / {_fmt(None if dev is None else dev * 1000, 1)} mm")
    add("sim_follows_plan", held, numbers, "S length ratio / mean deviation: " + "; ".join(parts) if parts
        else "needs simulated runs")

    # 5, 6, 9: T against S, every planner
    for key, metric, rel in (("field_slower", "execution_time_s", ">"), ("field_deviates_more", "deviation_mean_m", ">"),
                             ("field_less_clearance", "clearance_min_m", "<")):
        if key == "field_less_clearance":
            continue  # reported last, after the two findings on ratios
        add(key, *_t_vs_s(both, metric, rel, mode_mean))

    # 7: length ratios similar
    numbers, parts = {}, []
    held = None
    if both:
        held = True
        for p in both:
            s, t = mode_mean(p, "sim", "length_ratio"), mode_mean(p, "twb", "length_ratio")
            numbers[f"{p}_sim_length_ratio"], numbers[f"{p}_twb_length_ratio"] = _r(s), _r(t)
            ok = s is not None and t is not None and abs(t - s) <= SIMILAR_LENGTH_RATIO
            held = held and ok
            parts.append(f"{p} S {_fmt(s)} T {_fmt(t)}")
    add("length_similar", held, numbers, "; ".join(parts) if parts else "needs simulated and field runs")

    # 8: PRM smoother on the field
    numbers = {}
    if "prm" in both:
        t_ratio = {p: mode_mean(p, "twb", "smoothness_ratio") for p in both}
        s_prm = mode_mean("prm", "sim", "smoothness_ratio")
        numbers = {f"{p}_twb_smoothness_ratio": _r(v) for p, v in t_ratio.items()}
        numbers["prm_sim_smoothness_ratio"] = _r(s_prm)
        tp = t_ratio["prm"]
        held = (tp is not None and s_prm is not None and tp < 1 and tp < s_prm
                and all(v is None or tp <= v for v in t_ratio.values()))
        detail = (f"prm T {_fmt(tp)} (S {_fmt(s_prm)}); " +
                  ", ".join(f"{p} T {_fmt(v)}" for p, v in t_ratio.items() if p != "prm"))
        add("prm_smoother_on_field", held, numbers, detail)
    else:
        add("prm_smoother_on_field", None, numbers, "needs simulated and field runs of PRM")

    add("field_less_clearance", *_t_vs_s(both, "clearance_min_m", "<", mode_mean))
    return out


def _t_vs_s(planners: list[str], metric: str, rel: str, mode_mean: Any) -> tuple[Optional[bool], dict[str, Any], str]:
    numbers: dict[str, Any] = {}
    if not planners:
        return None, numbers, "needs simulated and field runs"
    held = True
    parts = []
    for p in planners:
        s, t = mode_mean(p, "sim", metric), mode_mean(p, "twb", metric)
        numbers[f"{p}_sim_{metric}"], numbers[f"{p}_twb_{metric}"] = _r(s, 5), _r(t, 5)
        ok = s is not None and t is not None and (t > s if rel == ">" else t < s)
        held = held and ok
        parts.append(f"{p} T {_fmt(t)} {rel} S {_fmt(s)}")
    return held, numbers, f"{metric}: " + "; ".join(parts)


def _verdict(held: Optional[bool]) -> str:
    return "n/a" if held is None else ("held" if held else "NOT held")


def findings_markdown(findings: list[Finding]) -> str:
    """The findings as a Markdown table: finding, check, numbers, verdict."""
    n = sum(f.held is True for f in findings)
    applicable = sum(f.held is not None for f in findings)
    lines = ["# The paper's findings", "", f"{n} of {applicable} applicable findings held "
             f"({len(findings)} checked; docs/fidelity.md explains each check).", "",
             "| # | finding | check | numbers | verdict |", "|---|---|---|---|---|"]
    for i, f in enumerate(findings, 1):
        cells = [str(i), f.claim, f.check, f.detail, _verdict(f.held)]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def findings_json(findings: list[Finding]) -> dict[str, Any]:
    """The findings as a JSON-ready document."""
    return {"held": sum(f.held is True for f in findings), "applicable": sum(f.held is not None for f in findings),
            "findings": [f.to_json() for f in findings]}


def write_findings(data: StudyData, directory: Optional[Path] = None) -> list[Finding]:
    """Check the findings on ``data`` and write ``findings.md`` and ``findings.json`` (default: the study's directory)."""
    found = paper_findings(data)
    d = Path(directory or data.directory or ".")
    d.mkdir(parents=True, exist_ok=True)
    (d / "findings.md").write_text(findings_markdown(found))
    (d / "findings.json").write_text(json.dumps(findings_json(found), indent=1, allow_nan=False) + "\n")
    return found


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)
