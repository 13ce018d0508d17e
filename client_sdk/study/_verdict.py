"""The answer in words: which configuration is better, per mode, with its uncertainty.

Built from the outcomes (:mod:`._outcomes`) and the comparisons (:mod:`._compare`):
per mode (the field first) a sentence on how often each configuration reached
the goal, then per pair of configurations the success-rate comparison, the
metrics that differ significantly after Holm's correction, and a verdict:

- a configuration is **better** when it reached the goal significantly more
  often;
- otherwise, when every significant metric difference favours one of them, it
  is better *on those metrics*; when they point both ways, it is a trade-off;
- otherwise there is no significant difference: the data cannot tell them
  apart (which is not the same as "equal").

The verdict is drawn over problems (each problem one observation) when the study
has at least three; then the words also say how the problems split ("FMM is
shorter on 5 of 6 problems; on room B it is longer") and whether they disagree.
With fewer problems there is no verdict over problems: each problem gets its own,
and the words say that one problem's answer says nothing about others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

from contract.vocabulary import Mode
from planners.comparisons import problem_name
from planners.stats import MIN_PROBLEMS

from ._compare import DIRECTION, Comparison, Comparisons, compared_over
from ._data import StudyData
from ._fleet_results import FLEET_METRICS
from ._outcomes import OutcomeSummary

__all__ = ["METRIC_WORDS", "MODE_WORDS", "Answer", "display_name", "fmt_p", "which_is_better"]

#: metric -> (name in a sentence, unit, decimals)
METRIC_WORDS = {
    "length_m": ("path length", "m", 3),
    "execution_time_s": ("execution time", "s", 2),
    "average_speed_m_s": ("average speed", "m/s", 3),
    "deviation_mean_m": ("mean deviation from the plan", "m", 4),
    "smoothness_rad": ("smoothness κ'", "rad", 3),
    "clearance_min_m": ("minimum clearance", "m", 4),
    "cross_track_error_mean_m": ("mean cross-track error", "m", 4),
    "heading_error_rms_rad": ("heading error RMS", "rad", 3),
    "time_to_goal_s": ("time to goal", "s", 2),
    "jerk_linear_rms_m_s3": ("linear jerk RMS", "m/s³", 3),
    **{m: (spec.words, spec.unit, spec.decimals) for m, spec in FLEET_METRICS.items()},
}
#: what success is, in a sentence: a single robot's, a fleet's
REACH = {False: "reached the goal", True: "got every robot to its goal"}
MODE_WORDS = {"twb": "On the field (Teleworkbench)", "sim": "In simulation"}
_TESTS = {"welch-t": "Welch's t", "paired-t": "paired t", "mann-whitney-u": "Mann-Whitney U", "wilcoxon": "Wilcoxon",
          "fisher-exact": "Fisher's exact", "problem-t": "t over problems",
          "problem-wilcoxon": "Wilcoxon signed-rank over problems", "problem-sign": "sign test over problems"}
_EFFECTS = {"hedges-g": "Hedges' g", "cohen-dz": "Cohen's d_z", "risk-difference": "risk difference",
            "problem-dz": "d over problems"}


def display_name(name: str) -> str:
    """A configuration as the paper writes it: ``fm2`` -> FM², ``fmm`` -> FMM, ``prm`` -> PRM, ``astar`` -> A*."""
    return {"fm2": "FM²", "fmm": "FMM", "prm": "PRM", "astar": "A*"}.get(name, name)


def fmt_p(p: float) -> str:
    """``p = 0.0079``, ``p < 0.001``, ``p = 1``."""
    if not math.isfinite(p):
        return "no p-value"
    return "p < 0.001" if p < 0.001 else f"p = {p:.2g}"


def _num(v: float, decimals: int) -> str:
    return f"{v:.{decimals}f}"


@dataclass
class Answer:
    """One mode's answer: ``verdicts`` (one line per pair), ``facts`` (outcomes, then the evidence)."""

    mode: str
    title: str
    verdicts: list[str] = field(default_factory=list)
    facts: list[str] = field(default_factory=list)


def _outcome_sentence(o: OutcomeSummary, reach: str = REACH[False]) -> str:
    name = display_name(o.configuration)
    if not o.counted:
        why = f"its {o.not_submitted} run(s) were refused by the testbed" if o.not_submitted else "no run ended"
        return f"{name}: no counted run ({why})."
    s = o.success
    parts = [f"{name} {reach} in {o.successes} of {o.counted} runs"]
    if s.get("rate") is not None:
        parts.append(f" (95% CI {100 * s['ci_low']:.0f}–{100 * s['ci_high']:.0f} %)")
    fails = []
    for col, word in (("collision", "collided"), ("timeout", "timed out")):
        n = o.count(col)
        if n:
            fails.append(f"{word} {'once' if n == 1 else f'{n} times'}")
    if o.count("other"):
        fails.append(f"failed otherwise: {o.other_detail}")
    if fails:
        parts.append("; " + ", ".join(fails))
    extra = []
    if o.identical:
        extra.append(f"identical repetitions (deterministic simulation): {s['n']} distinct run(s)")
    left = o.not_counted
    if left:
        extra.append(f"{left} run(s) not counted (testbed error, cancelled or refused)")
    if extra:
        parts.append(" — " + "; ".join(extra))
    return "".join(parts) + "."


def _rate_sentence(c: Comparison, alpha: float, reach: str = REACH[False]) -> str:
    r = c.result
    a, b = display_name(c.a), display_name(c.b)
    if c.pooled:
        return _pooled_rate_sentence(c, alpha, reach)
    if not c.tested:
        return f"Success rates of {a} and {b}: not compared ({c.note or r.note})."
    counts = f"{r.k_a}/{r.n_a} vs {r.k_b}/{r.n_b}"
    ci = c.confidence_interval()
    p = f"Fisher's exact {fmt_p(r.pvalue)}, Holm-adjusted {fmt_p(c.pvalue_holm)}" + (f"; {c.note}" if c.note else "")
    if r.k_a * r.n_b == r.k_b * r.n_a:
        return f"{a} and {b} {reach} equally often ({counts}; {p})."
    w, l_ = (a, b) if r.difference > 0 else (b, a)
    lo, hi = (ci.low, ci.high) if r.difference > 0 else (-ci.high, -ci.low)
    diff = f"{100 * abs(r.difference):.0f} percentage points (95% CI {100 * lo:+.0f} to {100 * hi:+.0f})"
    if c.significant(alpha):
        return f"{w} {reach} significantly more often than {l_}: {counts}, {diff}; {p}."
    return f"The success rates do not differ significantly ({counts}: {w} ahead by {diff}; {p})."


def _pooled_rate_sentence(c: Comparison, alpha: float, reach: str) -> str:
    """A success-rate comparison over problems: the mean of the problems' rates and of their differences."""
    r = c.result
    a, b = display_name(c.a), display_name(c.b)
    ci = c.confidence_interval()
    over = f"over {r.n_problems} problems"
    if not c.tested:
        return (f"Success rates of {a} and {b} {over}: {100 * r.mean_a:.0f} % vs {100 * r.mean_b:.0f} % on average "
                f"(not tested: {c.note or r.note}).")
    interval = (f"95% CI {100 * ci.low:+.0f} to {100 * ci.high:+.0f}; " if math.isfinite(ci.low) else
                f"the same on all {r.n_problems} problems, so no interval; ")
    diff = (f"{100 * r.difference:+.0f} percentage points ({interval}"
            f"{_TESTS.get(r.test, r.test)} {fmt_p(r.pvalue)}, Holm-adjusted {fmt_p(c.pvalue_holm)})")
    w, l_ = (a, b) if r.difference > 0 else (b, a)
    if c.significant(alpha):
        return f"{w} {reach} significantly more often than {l_} {over}: {diff}."
    if max(c.favouring()[:2]) == r.n_problems:
        return (f"{w} {reach} more often than {l_} on every one of the {r.n_problems} problems, but over so few "
                f"problems that is not significant: {diff}.")
    return f"The success rates {over} do not differ significantly: {a} − {b} {diff}."


def _metric_sentence(c: Comparison) -> str:
    r = c.result
    words, unit, dec = METRIC_WORDS.get(c.metric, (c.metric, "", 3))
    a, b = display_name(c.a), display_name(c.b)
    ci = c.confidence_interval()
    n = (f"{r.n_problems} problems, {r.n_a} and {r.n_b} runs" if c.pooled else
         f"{r.n_a} pairs" if r.paired else f"n = {r.n_a} and {r.n_b}")
    favour = c.better()
    tail = f" — in favour of {display_name(favour)}" if favour else ""
    level = 1 - r.confidence_level
    if math.isfinite(ci.low) and math.isfinite(ci.high) and (r.pvalue < level) == (ci.low <= 0 <= ci.high):
        tail += " (marginal: the interval and the test disagree)"
    effect = f"{_EFFECTS.get(r.effect, r.effect)} = {r.effect_size:.2g}" if math.isfinite(r.effect_size) else ""
    unit = f" {unit}" if unit else ""
    interval = (f"95% CI {ci.low:+.{dec}f} to {ci.high:+.{dec}f}" if math.isfinite(ci.low) and math.isfinite(ci.high)
                else "no interval: too few problems" if c.pooled else "no interval: too few runs for the bootstrap")
    return (f"{words.capitalize()}: {a} {_num(r.mean_a, dec)} vs {b} {_num(r.mean_b, dec)}{unit}, difference "
            f"{r.difference:+.{dec}f}{unit} ({interval}; {n}; "
            f"{_TESTS.get(r.test, r.test)} {fmt_p(r.pvalue)}, Holm-adjusted {fmt_p(c.pvalue_holm)}"
            f"{'; ' + effect if effect else ''}){tail}.")


def _words(metric: str) -> str:
    return METRIC_WORDS.get(metric, (metric,))[0]


def _judge(rows: list[Comparison], a: str, b: str, where: str, alpha: float,
           reach: str, brief: bool = False) -> tuple[Optional[str], list[str]]:
    """The verdict of one level (pooled over problems, or one problem) from its comparisons, and the facts.
    None for the verdict when nothing differs significantly (the caller words it for its level); ``brief``
    leaves the success rates out of a verdict on metrics (they are in the facts)."""
    facts = []
    an, bn = display_name(a), display_name(b)
    rate = next((c for c in rows if c.metric == "success_rate"), None)
    if rate is not None:
        facts.append(_rate_sentence(rate, alpha, reach))
    metrics = [c for c in rows if c.metric != "success_rate"]
    sig = [c for c in metrics if c.significant(alpha)]
    facts += [_metric_sentence(c) for c in sig]
    calm = [c for c in metrics if c.tested and not c.significant(alpha)]
    if calm:
        facts.append("No significant difference in " + ", ".join(_words(c.metric) for c in calm)
                     + f" (Holm-adjusted p > {alpha:g}).")
    untested: dict[str, list[str]] = {}
    for c in metrics:
        if not c.tested:
            untested.setdefault(c.note or c.result.note, []).append(_words(c.metric))
    for note, names in untested.items():
        facts.append(f"Not tested: {', '.join(names)} — {note}.")
    if rate is not None and not rate.pooled and rate.result.n_a and rate.result.n_b and \
            rate.result.k_a * rate.result.n_b != rate.result.k_b * rate.result.n_a and any(c.tested for c in metrics):
        wide = any(compared_over(c.metric) == "measured" for c in metrics)
        which = "the completed-run metrics" if wide else "the metrics"
        facts.append(f"Careful: {which} describe successful runs only — {an} {rate.result.k_a} of "
                     f"{rate.result.n_a}, {bn} {rate.result.k_b} of {rate.result.n_b} — so the one that fails "
                     "more is judged on its easier runs (survivor bias); read them with the success rates.")
    if rate is not None and rate.significant(alpha):
        w, l_ = (an, bn) if rate.difference > 0 else (bn, an)
        return f"{w} is better than {l_} {where}: it {reach} significantly more often.", facts
    judged = [c for c in sig if c.better() is not None]
    winners = {c.better() for c in judged}
    if len(winners) == 1:
        w = winners.pop()
        l_ = b if w == a else a
        on = ", ".join(_words(c.metric) for c in judged)
        if rate is None or not rate.tested or brief:
            rates = ""
        elif rate.difference == 0:
            rates = f"; both {reach} equally often"
        elif rate.pooled and max(rate.favouring()[:2]) == rate.result.n_problems:
            ahead = display_name(rate.a if rate.difference > 0 else rate.b)
            rates = (f"; {ahead} also {reach} more often on all {rate.result.n_problems} problems, short of "
                     f"significance over so few problems (Holm-adjusted {fmt_p(rate.pvalue_holm)})")
        else:
            rates = "; the success rates do not differ significantly"
        return f"{display_name(w)} is better than {display_name(l_)} {where} on {on}{rates}.", facts
    if len(winners) > 1:
        parts = [f"{display_name(w)} on " + ", ".join(_words(c.metric) for c in judged if c.better() == w)
                 for w in (a, b)]
        return f"A trade-off {where}: {parts[0]}; {parts[1]}.", facts
    return None, facts


def _problem_sentences(c: Comparison) -> list[str]:
    """How a pooled comparison's problems split, in words: "FMM is shorter on 5 of 6 problems; on room B it is
    longer (+0.120 m)." — and how much they disagree."""
    r = c.result
    words, unit, dec = METRIC_WORDS.get(c.metric, (c.metric, "", 3)) if c.metric != "success_rate" else \
        ("success rate", "", 2)
    a, b = display_name(c.a), display_name(c.b)
    k = r.n_problems
    fa, fb, ties = c.favouring() if c.direction else (r.favour_a, r.favour_b, r.ties)
    adj = {("length_m", -1): ("shorter", "longer"), ("execution_time_s", -1): ("faster", "slower"),
           ("time_to_goal_s", -1): ("faster", "slower"), ("clearance_min_m", 1): ("further from obstacles",
                                                                                "closer to obstacles"),
           ("success_rate", 1): ("more successful", "less successful")}
    good, bad = adj.get((c.metric, c.direction), ("better", "worse") if c.direction else ("higher", "lower"))
    lead, other = (a, b) if fa >= fb else (b, a)
    n_lead = max(fa, fb)
    unit_s = f" {unit}" if unit else ""
    out = [f"{words.capitalize()}: {lead} is {good} on {n_lead} of {k} problems" + (f" ({ties} tied)" if ties else "")]
    against = [(p, d) for p, d in zip(r.problems, r.differences)
               if (c.direction or 1) * d * (1 if lead == a else -1) < 0]
    if against and len(against) <= 3:
        out[0] += "; " + "; ".join(f"on {p} it is {bad} ({'+' if (lead == a) == (d > 0) else '-'}"
                                    f"{abs(d):.{dec}f}{unit_s})" for p, d in against)
    h = r.heterogeneity
    if math.isfinite(h.i2) and k >= 2:
        if h.i2 >= 0.5 and n_lead < k:
            out.append(f"the problems disagree (I² = {h.i2:.2f}: {100 * h.i2:.0f} % of the spread between problems "
                       "is real, not noise): which is better depends on the problem")
        elif h.i2 >= 0.5:
            out.append(f"the size of the difference varies between problems (I² = {h.i2:.2f})")
    return ["; ".join(out) + "."]


def _pair(mode: str, a: str, b: str, comps: Comparisons, alpha: float,
          reach: str = REACH[False]) -> tuple[str, list[str]]:
    where = {"twb": "on the field", "sim": "in simulation"}.get(mode, f"in {mode}")
    an, bn = display_name(a), display_name(b)
    mine = [c for c in comps if c.mode == mode and c.a == a and c.b == b]
    pooled = [c for c in mine if c.pooled]
    problems = list(dict.fromkeys(c.problem for c in mine if not c.pooled))
    facts: list[str] = []
    if pooled:
        verdict, facts = _judge(pooled, a, b, where, alpha, reach)
        k = max(c.result.n_problems for c in pooled)
        facts.insert(0, f"Over {k} problems (each problem one observation: the mean of its runs; the uncertainty "
                        "comes from how the problems differ, not from the runs):")
        for c in pooled:
            if c.result.ties == c.result.n_problems:
                continue  # the same on every problem: nothing to split
            if c.significant(alpha) or c.metric == "success_rate" or (
                    math.isfinite(c.result.heterogeneity.i2) and c.result.heterogeneity.i2 >= 0.5):
                facts += _problem_sentences(c)
        if verdict is None:
            unsure = [c for c in pooled if c.tested and not c.significant(alpha) and c.needed() is not None]
            more = ""
            if unsure:
                n = max(c.needed() for c in unsure)
                more = f" (about {n} problems would detect differences of the sizes seen with 80 % power)"
            verdict = (f"No significant difference between {an} and {bn} {where} over {k} problems: the data "
                       f"cannot tell them apart — more problems would{more}, more repetitions of the same "
                       "problems would not.")
        return verdict, facts
    if not problems:
        return f"{an} vs {bn} {where}: nothing to compare.", facts
    lines = []
    n = len(problems)
    for p in problems:
        rows = [c for c in mine if c.problem == p]
        name = problem_name(p)
        verdict, pf = _judge(rows, a, b, f"{where} on {name}" if n == 1 else f"on {name}", alpha, reach, n > 1)
        lines.append(verdict or f"no significant difference on {name}")
        facts += [f"{name}: {f}" for f in pf] if n > 1 else pf
    if n == 1:
        if verdict is None:
            return (f"No significant difference between {an} and {bn} {where} on {problem_name(problems[0])}: the "
                    "data cannot tell them apart on this problem (one problem says nothing about others)."), facts
        return lines[0] + " (One problem: its answer says nothing about other problems.)", facts
    return (f"With {n} problems there is no verdict over problems (at least {MIN_PROBLEMS} are needed); {where}: "
            + "; ".join(v.rstrip(".") for v in lines) + "."), facts


def which_is_better(data: StudyData, comparisons: Optional[Comparisons] = None,
                    outcomes: Optional[list[OutcomeSummary]] = None, alpha: float = 0.05) -> list[Answer]:
    """One :class:`Answer` per mode, the field first: verdicts per pair, then the facts behind them."""
    comps = comparisons if comparisons is not None else data.compare()
    outs = outcomes if outcomes is not None else data.outcomes()
    modes = sorted(data.modes, key=lambda m: (m != Mode.TWB, m))
    reach = REACH[data.spec.fleet]
    answers = []
    for mode in modes:
        ans = Answer(mode, MODE_WORDS.get(mode, mode))
        ans.facts += [_outcome_sentence(o, reach) for o in outs if o.mode == mode]
        pairs = list(dict.fromkeys((c.a, c.b) for c in comps if c.mode == mode))
        for a, b in pairs:
            verdict, facts = _pair(mode, a, b, comps, alpha, reach)
            ans.verdicts.append(verdict)
            if len(pairs) > 1:
                facts = [f"{display_name(a)} vs {display_name(b)}: {f}" for f in facts]
            ans.facts += facts
        if not pairs:
            ans.verdicts.append("Only one configuration: nothing to compare.")
        answers.append(ans)
    return answers


def direction_words() -> str:
    """How "better" is judged per metric, for the method note."""
    hi = [METRIC_WORDS[m][0] for m, d in DIRECTION.items() if d > 0 and m in METRIC_WORDS]
    lo = [METRIC_WORDS[m][0] for m, d in DIRECTION.items() if d < 0 and m in METRIC_WORDS]
    return f"higher is better for the success rate and {', '.join(hi)}; lower is better for {', '.join(lo)}"
