"""The paper's qualitative findings, checked on a study's data.

Tanoto et al. (*Teletesting*, §IV, Fig. 6 and 7) compare the paths FMM, FM² and
PRM compute with what a simulated robot (S) and the Teleworkbench's real robots
(T) drove, and the two drives with each other (ST).  :func:`paper_findings`
turns every claim of the results section into a check (:data:`FINDINGS`, in the
order of the paper's text: the computed paths, then claims 1-8 of issue 33).  Each compares per-planner means over the
study's completed runs (the bars of Fig. 6 and 7), paired across modes (a repetition whose run failed in one mode
is left out of every mode's mean: the modes are compared on the same computed paths), with a stated threshold, and
comes back with the numbers behind it and whether it held.  It is a pure
function of a :class:`~client_sdk.study.StudyData`, so a study directory is
enough, offline.  docs/fidelity.md explains each check and the mechanism of the
emulated field that makes it hold.

A check needs the planners and modes it speaks of; without them it is *not
applicable* (``held`` is None), never passed by default.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from ._data import StudyData
from ._figures import mean_std

__all__ = ["FINDINGS", "Finding", "findings_json", "findings_markdown", "paper_findings", "write_findings"]

#: |S length ratio − 1| at most this: the simulated robot drives the planned length
SIM_LENGTH_TOLERANCE = 0.03
#: S mean deviation below this (m): the simulated robot stays on the computed path
SIM_DEVIATION_MAX_M = 0.01
#: |T length ratio − S length ratio| at most this: "similar" length deviation
SIMILAR_LENGTH_RATIO = 0.05
#: "the size of that gap is not the same for every planner": the T − S execution time gaps (s) differ by at
#: least this share of their mean
GAP_DIFFERS = 0.1
#: "by an almost constant amount across planners": the T − S mean deviation gaps differ by at most this
#: share of their mean
GAP_CONSTANT = 0.5
#: "the deviations between simulation and the real world are not constant across planners": in at least
#: :data:`DIFFERS_IN` of the :data:`FIG6_METRICS` the planners' relative gaps (T / S − 1) differ by at least this
#: share of the largest
GAPS_DIFFER = 0.2
DIFFERS_IN = 2
FIG6_METRICS = ("execution_time_s", "length_m", "deviation_mean_m", "clearance_min_m", "smoothness_rad")
PLANNERS = ("fmm", "fm2", "prm")


@dataclass(frozen=True)
class Finding:
    """One of the paper's claims, checked: ``held`` is True, False or None (not applicable)."""

    key: str
    claim: str  #: the paper's claim
    check: str  #: how it is checked: metric, comparison, threshold
    held: Optional[bool]
    numbers: dict[str, Any] = field(default_factory=dict)  #: the means behind the verdict
    detail: str = ""  #: the comparison with its numbers, one line

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


#: key -> (claim, check) of the paper's findings, in the order they are reported
FINDINGS: dict[str, tuple[str, str]] = {
    "fmm_shortest": ("FMM computes the shortest paths.",
                     "computed paths: mean length of FMM ≤ that of FM² and of PRM"),
    "fm2_safest": ("FM² computes the safest paths, with the largest clearance.",
                   "computed paths: mean minimum clearance of FM² > that of FMM and of PRM"),
    "prm_sharpest": ("PRM's paths are characterised by sharp curves: they are the least smooth.",
                     "computed paths: mean κ' of PRM > that of FMM and of FM²"),
    "sim_follows_plan": ("In simulation the robot drives the computed path almost exactly.",
                         f"every planner: |S length ratio − 1| ≤ {SIM_LENGTH_TOLERANCE:g} and S mean deviation "
                         f"< {SIM_DEVIATION_MAX_M * 1000:g} mm"),
    "field_slower": ("Real runs take longer than simulated ones: the real robot is slower.",
                     "every planner: mean execution time T > S and mean average speed T < S"),
    "slowdown_differs": ("The size of the time gap between real and simulated runs is not the same for every "
                         "planner.",
                         f"T − S mean execution time per planner: max − min ≥ {GAP_DIFFERS:g} × their mean"),
    "field_deviates_more": ("The real robot deviates more from the computed path than the simulated one.",
                            "every planner: mean deviation T > S"),
    "deviation_gap_constant": ("Path deviation is higher on the real field by an almost constant amount across "
                               "planners.",
                               f"T − S mean deviation per planner: max − min ≤ {GAP_CONSTANT:g} × their mean"),
    "field_less_clearance": ("Minimum clearance follows the same pattern: lower on the real field.",
                             "every planner: mean minimum clearance T < S"),
    "length_similar": ("Path length deviation shows similar results in simulation and in real experiments.",
                       f"every planner: |mean T length ratio − mean S length ratio| ≤ {SIMILAR_LENGTH_RATIO:g}"),
    "smoothness_not_reproduced": ("The controller does not reproduce the paths as smooth as they were planned.",
                                  "every planner but PRM (its exception: finding prm_smoother_on_field): T κ' ratio "
                                  "(mean performed κ' / mean computed κ') > 1"),
    "prm_least_smoothness_difference": ("The least difference in smoothness between simulation and real "
                                        "experiments is PRM's.",
                                        "|T κ' ratio − S κ' ratio| of PRM < that of FMM and of FM²"),
    "field_ratios_worse": ("Ratios to the computed path: the real experiments are always worse than the "
                           "simulation, with one exception: PRM's smoothness.",
                           "every planner: mean length ratio T > S, mean clearance ratio T < S; κ' ratio T > S "
                           "for every planner but PRM (the exception, \"improved on the real robot\": finding "
                           "prm_smoother_on_field, T κ' ratio < 1)"),
    "field_length_ratio_above_1": ("The real path-length ratio is above 1 for every planner: the path length has "
                                   "increased.",
                                   "every planner: mean T length ratio > 1"),
    "prm_smoother_on_field": ("The smoothness of PRM is improved on the real robot: the controller cannot follow "
                              "the sharp curves a PRM path is characterised by.",
                              "T smoothness ratio (mean T κ' / mean computed κ', over the field runs) of PRM < 1 "
                              "and < that of FMM and of FM²"),
    "field_overshoots_more": ("Overshoots (the P-controller not keeping the robot on track) are more prevalent on "
                              "the real field.",
                              "every planner: mean maximum deviation from the computed path T > S"),
    "field_paths_longer": ("The experiments on the real field produce longer robot paths than the simulation.",
                           "every planner: mean path length T > S"),
    "deviations_differ_across_planners": ("The deviations between simulation and the real world are not constant "
                                          "across planners.",
                                          f"relative gap T / S − 1 of each planner's mean time, length, deviation, "
                                          f"minimum clearance, κ': in at least {DIFFERS_IN} of these the planners' "
                                          f"gaps differ by ≥ {GAPS_DIFFER:g} × the largest |gap|"),
}


def _fmt(x: Optional[float], digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def _r(x: Optional[float], digits: int = 5) -> Optional[float]:
    return None if x is None else round(x, digits)


class _Means:
    """Per-planner means of a study's completed runs, paired: a repetition counts only where it completed in every
    mode its experiment ran (the same computed path driven in simulation and on the field), so that a run failing
    in one mode does not take its path out of that mode's mean alone (a randomised planner's paths differ per
    repetition; the failed runs are the study's outcomes, not these means')."""

    def __init__(self, data: StudyData) -> None:
        ran: dict[Any, set[str]] = {}
        completed: dict[tuple[Any, Any], set[str]] = {}
        for r in data.rows:
            ran.setdefault(r["experiment_id"], set()).add(r["mode"])
            if r.get("status") == "completed":
                completed.setdefault((r["experiment_id"], r.get("repetition")), set()).add(r["mode"])
        self.done = [r for r in data.rows if r.get("status") == "completed"
                     and completed[(r["experiment_id"], r.get("repetition"))] >= ran[r["experiment_id"]]]
        self.direct = data.direct

    def runs(self, planner: str, mode: str) -> list[dict[str, Any]]:
        return [r for r in self.done if r["planner"] == planner and r["mode"] == mode]

    def mode(self, planner: str, mode: str, key: str) -> Optional[float]:
        return mean_std(r.get(key) for r in self.runs(planner, mode))[0]

    def planned(self, planner: str, key: str) -> Optional[float]:
        """Mean over the planner's experiments (each once) of the computed path's ``key``."""
        per_exp = {r["experiment_id"]: r.get(f"planned_{key}") for r in self.done if r["planner"] == planner}
        return mean_std(per_exp.values())[0]

    def st(self, planner: str, key: str) -> Optional[float]:
        return mean_std(d.get(key) for d in self.direct if d["planner"] == planner)[0]

    def has(self, planner: str, *modes: str) -> bool:
        return all(self.runs(planner, m) for m in modes)


def paper_findings(data: StudyData) -> list[Finding]:
    """The paper's findings (:data:`FINDINGS`) on ``data``'s completed runs, in that order; a fleet study's are
    all not applicable (the paper measured one robot at a time)."""
    if data.spec.fleet:
        return [_finding(key, None, {}, "a fleet study: the paper's findings concern one robot") for key in FINDINGS]
    m = _Means(data)
    both = [p for p in dict.fromkeys(r["planner"] for r in m.done) if m.has(p, "sim", "twb")]
    found = [
        _planned_best(m, "fmm_shortest", "length_m", "fmm", lower=True),
        _planned_best(m, "fm2_safest", "clearance_min_m", "fm2", lower=False),
        _planned_best(m, "prm_sharpest", "smoothness_rad", "prm", lower=False),
        _sim_follows_plan(m),
        _every_planner(m, "field_slower", both, [("execution_time_s", ">", 1.0, "s"), ("average_speed_m_s", "<", 1.0, "m/s")]),
        _gap_spread(m, "slowdown_differs", both, "execution_time_s", 1.0, "s", at_least=GAP_DIFFERS),
        _every_planner(m, "field_deviates_more", both, [("deviation_mean_m", ">", 1000.0, "mm")]),
        _gap_spread(m, "deviation_gap_constant", both, "deviation_mean_m", 1000.0, "mm", at_most=GAP_CONSTANT),
        _every_planner(m, "field_less_clearance", both, [("clearance_min_m", "<", 1000.0, "mm")]),
        _length_similar(m, both),
        _smoothness_not_reproduced(m, both),
        _prm_least_smoothness_difference(m, both),
        _ratios_worse(m, both),
        _length_ratio_above_1(m, both),
        _prm_smoother(m, both),
        _every_planner(m, "field_overshoots_more", both, [("deviation_max_m", ">", 1000.0, "mm")]),
        _every_planner(m, "field_paths_longer", both, [("length_m", ">", 1.0, "m")]),
        _gaps_differ(m, both),
    ]
    return found


def _finding(key: str, held: Optional[bool], numbers: dict[str, Any], detail: str) -> Finding:
    claim, check = FINDINGS[key]
    return Finding(key, claim, check, held, numbers, detail)


def _planned_best(m: _Means, key: str, metric: str, best: str, *, lower: bool) -> Finding:
    vals = {p: m.planned(p, metric) for p in PLANNERS}
    numbers = {f"{p}_planned_{metric}": _r(v) for p, v in vals.items()}
    if any(v is None for v in vals.values()):
        return _finding(key, None, numbers, "needs computed paths of FMM, FM² and PRM")
    b = vals[best]
    others = {p: v for p, v in vals.items() if p != best}
    held = all(b <= v for v in others.values()) if lower else all(b > v for v in others.values())
    rel = "≤" if lower else ">"
    detail = f"{metric}: {best} {_fmt(b)} {rel} " + ", ".join(f"{p} {_fmt(v)}" for p, v in others.items())
    return _finding(key, held, numbers, detail)


def _sim_follows_plan(m: _Means) -> Finding:
    planners = [p for p in dict.fromkeys(r["planner"] for r in m.done) if m.has(p, "sim")]
    if not planners:
        return _finding("sim_follows_plan", None, {}, "needs simulated runs")
    numbers: dict[str, Any] = {}
    held, parts = True, []
    for p in planners:
        lr, dev = m.mode(p, "sim", "length_ratio"), m.mode(p, "sim", "deviation_mean_m")
        numbers[f"{p}_sim_length_ratio"], numbers[f"{p}_sim_deviation_mean_m"] = _r(lr), _r(dev)
        held = held and lr is not None and dev is not None and abs(lr - 1) <= SIM_LENGTH_TOLERANCE \
            and dev < SIM_DEVIATION_MAX_M
        parts.append(f"{p} {_fmt(lr)} / {_fmt(None if dev is None else dev * 1000, 1)} mm")
    return _finding("sim_follows_plan", held, numbers, "S length ratio / mean deviation: " + "; ".join(parts))


_COMPARE: dict[str, Callable[[float, float], bool]] = {">": lambda a, b: a > b, "<": lambda a, b: a < b}


def _every_planner(m: _Means, key: str, planners: list[str], metrics: list[tuple[str, str, float, str]]) -> Finding:
    """T against S for every planner: ``T rel S`` for each (metric, rel, display scale, display unit)."""
    if not planners:
        return _finding(key, None, {}, "needs simulated and field runs")
    numbers: dict[str, Any] = {}
    held, parts = True, []
    for metric, rel, scale, unit in metrics:
        cells = []
        for p in planners:
            s, t = m.mode(p, "sim", metric), m.mode(p, "twb", metric)
            numbers[f"{p}_sim_{metric}"], numbers[f"{p}_twb_{metric}"] = _r(s), _r(t)
            held = held and s is not None and t is not None and _COMPARE[rel](t, s)
            digits = 1 if scale > 1 else 3
            cells.append(f"{p} T {_fmt(None if t is None else t * scale, digits)} {rel} "
                         f"S {_fmt(None if s is None else s * scale, digits)}")
        parts.append(f"{metric} ({unit}): " + ", ".join(cells))
    return _finding(key, held, numbers, "; ".join(parts))


def _length_similar(m: _Means, planners: list[str]) -> Finding:
    if not planners:
        return _finding("length_similar", None, {}, "needs simulated and field runs")
    numbers: dict[str, Any] = {}
    held, parts = True, []
    for p in planners:
        s, t = m.mode(p, "sim", "length_ratio"), m.mode(p, "twb", "length_ratio")
        numbers[f"{p}_sim_length_ratio"], numbers[f"{p}_twb_length_ratio"] = _r(s), _r(t)
        held = held and s is not None and t is not None and abs(t - s) <= SIMILAR_LENGTH_RATIO
        parts.append(f"{p} S {_fmt(s)} T {_fmt(t)}")
    return _finding("length_similar", held, numbers, "length ratio: " + "; ".join(parts))


def _prm_smoother(m: _Means, planners: list[str]) -> Finding:
    if "prm" not in planners:
        return _finding("prm_smoother_on_field", None, {}, "needs field runs of PRM")
    ratio = {p: _kappa_ratio(m, p, "twb") for p in planners}
    numbers = {f"{p}_twb_smoothness_ratio": _r(v) for p, v in ratio.items()}
    prm = ratio["prm"]
    held = prm is not None and prm < 1 and all(v is not None and prm < v for p, v in ratio.items() if p != "prm")
    return _finding("prm_smoother_on_field", held, numbers,
                    "T κ' / computed κ': " + ", ".join(f"{p} {_fmt(v)}" for p, v in ratio.items()))


def _spread(values: dict[str, float]) -> tuple[float, float]:
    """(max − min, mean) of the planners' values."""
    v = list(values.values())
    return max(v) - min(v), sum(v) / len(v)


def _gap_spread(m: _Means, key: str, planners: list[str], metric: str, scale: float, unit: str, *,
                at_least: Optional[float] = None, at_most: Optional[float] = None) -> Finding:
    """The planners' T − S gaps of ``metric``: their spread (max − min) at least / at most a share of their mean
    (``at_least`` / ``at_most``); needs two planners."""
    if len(planners) < 2:
        return _finding(key, None, {}, "needs simulated and field runs of two planners")
    gaps: dict[str, float] = {}
    numbers: dict[str, Any] = {}
    for p in planners:
        s, t = m.mode(p, "sim", metric), m.mode(p, "twb", metric)
        if s is None or t is None:
            return _finding(key, None, numbers, f"needs {metric} of every planner")
        gaps[p] = t - s
        numbers[f"{p}_gap_{metric}"] = _r(t - s)
    spread, mean = _spread(gaps)
    numbers["spread"], numbers["mean"] = _r(spread), _r(mean)
    if at_least is not None:
        held, rel, share = spread >= at_least * abs(mean), "≥", at_least
    else:
        held, rel, share = mean > 0 and spread <= (at_most or 0.0) * mean, "≤", at_most
    cells = ", ".join(f"{p} {g * scale:+.{1 if scale > 1 else 2}f}" for p, g in gaps.items())
    return _finding(key, held, numbers, f"T − S {metric} ({unit}): {cells}; max − min {spread * scale:.2f} {rel} "
                                        f"{share:g} × mean {mean * scale:.2f}")


def _kappa_ratio(m: _Means, p: str, mode: str) -> Optional[float]:
    """Mean performed κ' / mean computed κ' over ``p``'s runs in ``mode`` (a ratio of means: a nearly
    straight computed path would make a mean of per-run ratios explode)."""
    runs = m.runs(p, mode)
    t = mean_std(r.get("smoothness_rad") for r in runs)[0]
    c = mean_std(r.get("planned_smoothness_rad") for r in runs)[0]
    return None if t is None or c is None or c <= 0 else t / c


def _smoothness_not_reproduced(m: _Means, planners: list[str]) -> Finding:
    others = [p for p in planners if p != "prm"]
    if not others:
        return _finding("smoothness_not_reproduced", None, {}, "needs field runs of a planner other than PRM")
    ratio = {p: _kappa_ratio(m, p, "twb") for p in others}
    numbers = {f"{p}_twb_smoothness_ratio": _r(v) for p, v in ratio.items()}
    held = all(v is not None and v > 1 for v in ratio.values())
    return _finding("smoothness_not_reproduced", held, numbers,
                    "T κ' / computed κ': " + ", ".join(f"{p} {_fmt(v)}" for p, v in ratio.items()))


def _prm_least_smoothness_difference(m: _Means, planners: list[str]) -> Finding:
    key = "prm_least_smoothness_difference"
    if "prm" not in planners or len(planners) < 2:
        return _finding(key, None, {}, "needs simulated and field runs of PRM and another planner")
    diff: dict[str, Optional[float]] = {}
    for p in planners:
        s, t = _kappa_ratio(m, p, "sim"), _kappa_ratio(m, p, "twb")
        diff[p] = None if s is None or t is None else abs(t - s)
    numbers = {f"{p}_smoothness_ratio_difference": _r(v) for p, v in diff.items()}
    prm = diff["prm"]
    held = prm is not None and all(v is not None and prm < v for p, v in diff.items() if p != "prm")
    return _finding(key, held, numbers, "|T − S| κ' ratio: " + ", ".join(f"{p} {_fmt(v)}" for p, v in diff.items()))


def _ratios_worse(m: _Means, planners: list[str]) -> Finding:
    """Fig. 7: length ratio higher, clearance ratio lower, κ' ratio higher on the field; PRM's κ' ratio lower."""
    if not planners:
        return _finding("field_ratios_worse", None, {}, "needs simulated and field runs")
    numbers: dict[str, Any] = {}
    held, parts = True, []
    for p in planners:
        ls, lt = m.mode(p, "sim", "length_ratio"), m.mode(p, "twb", "length_ratio")
        cs, ct = m.mode(p, "sim", "clearance_ratio"), m.mode(p, "twb", "clearance_ratio")
        ks, kt = _kappa_ratio(m, p, "sim"), _kappa_ratio(m, p, "twb")
        for name, s, t in (("length", ls, lt), ("clearance", cs, ct), ("smoothness", ks, kt)):
            numbers[f"{p}_sim_{name}_ratio"], numbers[f"{p}_twb_{name}_ratio"] = _r(s), _r(t)
        if None in (ls, lt, cs, ct, ks, kt):
            held = False
            parts.append(f"{p}: missing ratios")
            continue
        k_ok = p == "prm" or kt > ks  # PRM's: the exception (prm_smoother_on_field); numbers keeps T vs S
        held = held and lt > ls and ct < cs and k_ok
        parts.append(f"{p} length {_fmt(lt)} vs {_fmt(ls)}, clearance {_fmt(ct)} vs {_fmt(cs)}, "
                     f"κ' {_fmt(kt)} vs {_fmt(ks)}")
    return _finding("field_ratios_worse", held, numbers, "T vs S ratios: " + "; ".join(parts))


def _length_ratio_above_1(m: _Means, planners: list[str]) -> Finding:
    if not planners:
        return _finding("field_length_ratio_above_1", None, {}, "needs simulated and field runs")
    ratio = {p: m.mode(p, "twb", "length_ratio") for p in planners}
    numbers = {f"{p}_twb_length_ratio": _r(v) for p, v in ratio.items()}
    held = all(v is not None and v > 1 for v in ratio.values())
    return _finding("field_length_ratio_above_1", held, numbers,
                    "T length ratio: " + ", ".join(f"{p} {_fmt(v, 4)}" for p, v in ratio.items()))


def _gaps_differ(m: _Means, planners: list[str]) -> Finding:
    key = "deviations_differ_across_planners"
    if len(planners) < 2:
        return _finding(key, None, {}, "needs simulated and field runs of two planners")
    numbers: dict[str, Any] = {}
    differ, parts = [], []
    for metric in FIG6_METRICS:
        gaps = {}
        for p in planners:
            s, t = m.mode(p, "sim", metric), m.mode(p, "twb", metric)
            if s is not None and t is not None and s != 0:
                gaps[p] = t / s - 1
                numbers[f"{p}_relative_gap_{metric}"] = _r(gaps[p])
        if len(gaps) < 2:
            continue
        spread, largest = _spread(gaps)[0], max(abs(g) for g in gaps.values())
        if largest > 0 and spread >= GAPS_DIFFER * largest:
            differ.append(metric)
        parts.append(f"{metric} " + "/".join(f"{g:+.3f}" for g in gaps.values()))
    numbers["differ_in"] = differ
    return _finding(key, len(differ) >= DIFFERS_IN, numbers,
                    f"T / S − 1 ({'/'.join(planners)}): {'; '.join(parts)}; differ in {len(differ)}: "
                    + (", ".join(differ) or "none"))


def _verdict(held: Optional[bool]) -> str:
    return "n/a" if held is None else ("held" if held else "NOT held")


def findings_markdown(findings: list[Finding]) -> str:
    """The findings as a Markdown table: finding, check, numbers, verdict."""
    held = sum(f.held is True for f in findings)
    applicable = sum(f.held is not None for f in findings)
    lines = ["# The paper's findings", "",
             f"{held} of {applicable} applicable findings held ({len(findings)} checked; docs/fidelity.md "
             "explains each check). S = simulation, T = Teleworkbench (the field).", "",
             "| # | finding | check | numbers | verdict |", "|---|---|---|---|---|"]
    for i, f in enumerate(findings, 1):
        cells = [str(i), f.claim, f.check, f.detail, _verdict(f.held)]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def findings_json(findings: list[Finding]) -> dict[str, Any]:
    """The findings as a JSON-ready document: counts and every finding."""
    return {"held": sum(f.held is True for f in findings), "applicable": sum(f.held is not None for f in findings),
            "findings": [f.to_json() for f in findings]}


def write_findings(data: StudyData, directory: Optional[Path] = None) -> list[Finding]:
    """Check the findings on ``data``; write ``findings.md`` and ``findings.json`` into ``directory``
    (default: the study's), except for a fleet study (all n/a: the findings concern one robot).
    Returns the findings."""
    found = paper_findings(data)
    if data.spec.fleet:
        return found
    d = Path(directory or data.directory or ".")
    d.mkdir(parents=True, exist_ok=True)
    (d / "findings.md").write_text(findings_markdown(found))
    (d / "findings.json").write_text(json.dumps(findings_json(found), indent=1, ensure_ascii=False) + "\n")
    return found
