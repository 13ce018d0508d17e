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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

from contract.vocabulary import Mode

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
          "fisher-exact": "Fisher's exact"}
_EFFECTS = {"hedges-g": "Hedges' g", "cohen-dz": "Cohen's d_z", "risk-difference": "risk difference"}


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


def _metric_sentence(c: Comparison) -> str:
    r = c.result
    words, unit, dec = METRIC_WORDS.get(c.metric, (c.metric, "", 3))
    a, b = display_name(c.a), display_name(c.b)
    ci = c.confidence_interval()
    n = f"{r.n_a} pairs" if r.paired else f"n = {r.n_a} and {r.n_b}"
    favour = c.better()
    tail = f" — in favour of {display_name(favour)}" if favour else ""
    level = 1 - r.confidence_level
    if math.isfinite(ci.low) and math.isfinite(ci.high) and (r.pvalue < level) == (ci.low <= 0 <= ci.high):
        tail += " (marginal: the interval and the test disagree)"
    effect = f"{_EFFECTS.get(r.effect, r.effect)} = {r.effect_size:.2g}" if math.isfinite(r.effect_size) else ""
    unit = f" {unit}" if unit else ""
    interval = (f"95% CI {ci.low:+.{dec}f} to {ci.high:+.{dec}f}" if math.isfinite(ci.low) and math.isfinite(ci.high)
                else "no interval: too few runs for the bootstrap")
    return (f"{words.capitalize()}: {a} {_num(r.mean_a, dec)} vs {b} {_num(r.mean_b, dec)}{unit}, difference "
            f"{r.difference:+.{dec}f}{unit} ({interval}; {n}; "
            f"{_TESTS.get(r.test, r.test)} {fmt_p(r.pvalue)}, Holm-adjusted {fmt_p(c.pvalue_holm)}"
            f"{'; ' + effect if effect else ''}){tail}.")


def _pair(mode: str, a: str, b: str, comps: Comparisons, alpha: float,
          reach: str = REACH[False]) -> tuple[str, list[str]]:
    facts = []
    an, bn = display_name(a), display_name(b)
    rate = comps.get("success_rate", mode, a, b)
    if rate is not None:
        facts.append(_rate_sentence(rate, alpha, reach))
    metrics = [c for c in comps if c.mode == mode and c.a == a and c.b == b and c.metric != "success_rate"]
    sig = [c for c in metrics if c.significant(alpha)]
    facts += [_metric_sentence(c) for c in sig]
    calm = [c for c in metrics if c.tested and not c.significant(alpha)]
    if calm:
        facts.append("No significant difference in " + ", ".join(METRIC_WORDS.get(c.metric, (c.metric,))[0]
                                                                   for c in calm)
                     + f" (Holm-adjusted p > {alpha:g}).")
    untested: dict[str, list[str]] = {}
    for c in metrics:
        if not c.tested:
            untested.setdefault(c.note or c.result.note, []).append(METRIC_WORDS.get(c.metric, (c.metric,))[0])
    for note, names in untested.items():
        facts.append(f"Not tested: {', '.join(names)} — {note}.")
    if metrics and any(c.tested for c in metrics):
        paired = any(c.result.paired for c in metrics if c.tested)
        wide = [METRIC_WORDS.get(c.metric, (c.metric,))[0] for c in metrics if compared_over(c.metric) == "measured"]
        facts.append("Metrics are over completed runs" + (
            f" ({', '.join(wide)}: over every measured run, failed ones included)" if wide else "") + ", " + (
            "paired by problem and repetition." if paired else "unpaired (the two did not run the same problems "
                                                               "and repetitions)."))
        if rate is not None and rate.result.n_a and rate.result.n_b and \
                rate.result.k_a * rate.result.n_b != rate.result.k_b * rate.result.n_a:
            which = "the completed-run metrics" if wide else "they"
            facts.append(f"Careful: {which} describe successful runs only — {an} {rate.result.k_a} of "
                         f"{rate.result.n_a}, {bn} {rate.result.k_b} of {rate.result.n_b} — so the one that fails "
                         "more is judged on its easier runs (survivor bias); read them with the success rates.")
    where = {"twb": "on the field", "sim": "in simulation"}.get(mode, f"in {mode}")
    if rate is not None and rate.significant(alpha):
        w, l_ = (an, bn) if rate.difference > 0 else (bn, an)
        return f"{w} is better than {l_} {where}: it {reach} significantly more often.", facts
    judged = [c for c in sig if c.better() is not None]
    winners = {c.better() for c in judged}
    if len(winners) == 1:
        w = winners.pop()
        l_ = b if w == a else a
        on = ", ".join(METRIC_WORDS.get(c.metric, (c.metric,))[0] for c in judged)
        if rate is None or not rate.tested:
            rates = ""
        elif rate.result.k_a * rate.result.n_b == rate.result.k_b * rate.result.n_a:
            rates = f"; both {reach} equally often"
        else:
            rates = "; the success rates do not differ significantly"
        return f"{display_name(w)} is better than {display_name(l_)} {where} on {on}{rates}.", facts
    if len(winners) > 1:
        parts = [f"{display_name(w)} on " + ", ".join(METRIC_WORDS.get(c.metric, (c.metric,))[0]
                                                      for c in judged if c.better() == w) for w in (a, b)]
        return f"A trade-off {where}: {parts[0]}; {parts[1]}.", facts
    if not any(c.tested for c in metrics) and (rate is None or not rate.tested):
        return f"{an} vs {bn} {where}: nothing to test (see below).", facts
    return (f"No significant difference between {an} and {bn} {where}: the data cannot tell them apart "
            "(more repetitions, or jitter in simulation, would)."), facts


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
