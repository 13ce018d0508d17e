"""A study's summary (Markdown), figures and HTML report, written from its data."""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any, Optional

from contract.vocabulary import JUDGED
from planners.compared import FLEET_METHOD, METHOD
from planners.environment import InvalidEnvironment, load_environment
from planners.problems import stored_optimum

from ._compare import COMPARISON_COLUMNS, Comparisons
from ._data import StudyData, write_csv_rows
from ._figure_set import make_figures
from ._figures import mean_std, save_figures
from ._fleet_tables import fleet_tables, write_fleet_csvs
from ._outcomes import OutcomeSummary
from ._verdict import METRIC_WORDS, Answer, which_is_better
from ._worlds import difficulty_table

__all__ = ["SUMMARY_METRICS", "comparison_rows", "outcome_rows", "summary_markdown", "summary_tables",
           "which_is_better_markdown", "write_report"]

#: columns of the summary tables: (metric, header)
SUMMARY_METRICS = (
    ("length_m", "length (m)"),
    ("smoothness_rad", "κ' (rad)"),
    ("clearance_min_m", "min clearance (m)"),
    ("execution_time_s", "time (s)"),
    ("average_speed_m_s", "speed (m/s)"),
    ("deviation_mean_m", "mean dev. (m)"),
    ("deviation_max_m", "max dev. (m)"),
    ("length_ratio", "length ratio"),
    ("smoothness_ratio", "κ' ratio"),
    ("clearance_ratio", "clearance ratio"),
)
PLANNED_METRICS = (("length_m", "length (m)"), ("smoothness_rad", "κ' (rad)"), ("clearance_min_m", "min clearance (m)"),
                   ("aol_rad_per_m", "AOL (rad/m)"), ("planning_time_s", "planning time (s)"))
DIRECT_METRICS = (("deviation_mean_m", "mean dev. (m)"), ("deviation_max_m", "max dev. (m)"),
                  ("hausdorff_m", "Hausdorff (m)"), ("frechet_m", "Fréchet (m)"))


def _fmt(values: list[Any]) -> str:
    mean, std, n = mean_std(values)
    if mean is None:
        return "–"
    digits = 3 if abs(mean) < 100 else 1
    if n >= 2 and std is not None and std == 0:
        return f"{mean:.{digits}f} (identical ×{n})"
    return f"{mean:.{digits}f}" + (f" ± {std:.{digits}f}" if std is not None else "")


def _pct(v: Optional[float]) -> str:
    return "–" if v is None else f"{100 * v:.0f} %"


def outcome_rows(outcomes: list[OutcomeSummary]) -> tuple[list[str], list[list[str]]]:
    """The outcomes table: runs, success, collision, timeout, other failures, not counted, success rate (Wilson)."""
    header = ["configuration", "mode", "runs", "success", "collision", "timeout", "other failure", "not counted",
              "success rate (95% CI)"]
    body = []
    for o in outcomes:
        other = str(o.count("other")) + (f" ({o.other_detail})" if o.count("other") else "")
        body.append([o.configuration, o.mode, str(o.runs + o.not_submitted), str(o.successes), str(o.count("collision")),
                     str(o.count("timeout")), other, str(o.not_counted), o.rate_text()])
    return header, body


#: per-problem comparison rows a report shows at most; a larger study's are in comparisons.csv only (the planner
#: study's 12 planners on 7 problems made a summary.md of 5,880 lines, almost all of them per problem)
MAX_PROBLEM_ROWS = 200


def comparison_rows(comparisons: Comparisons, per_problem: bool = True) -> tuple[list[str], list[list[str]]]:
    """The comparisons table (a − b), as strings; ``per_problem`` False: only those over all problems."""
    header = ["metric", "mode", "a", "b", "problem", "n a", "n b", "mean a", "mean b", "diff (a − b)", "95% CI",
              "test", "p", "p (Holm)", "effect size", "problems a/b better", "I²", "n for 80% power", "note"]
    body = []
    for c in comparisons:
        if not (per_problem or c.pooled):
            continue
        r, ci = c.result, c.confidence_interval()
        dec = 3 if c.metric == "success_rate" else METRIC_WORDS.get(c.metric, ("", "", 3))[2]
        num = (lambda v: "–" if not math.isfinite(v) else f"{v:.{dec}f}")  # noqa: E731
        row = c.row()
        where = f"all {r.n_problems}" if c.pooled else row["problem"]
        split = f"{row['favour_a']}/{row['favour_b']}" if c.pooled else ""
        i2 = row["heterogeneity_i2"]
        need = "" if row["n_needed"] is None else f"{row['n_needed']} {row['needed_unit']}"
        body.append([c.metric, c.mode, c.a, c.b, where, str(r.n_a), str(r.n_b), num(r.mean_a), num(r.mean_b),
                     num(r.difference), "–" if not math.isfinite(ci.low) else f"[{num(ci.low)}, {num(ci.high)}]",
                     _TEST_NAMES.get(r.test, r.test or "–"), _p(r.pvalue), _p(c.pvalue_holm),
                     "–" if not math.isfinite(r.effect_size) else f"{_EFFECT_NAMES.get(r.effect, r.effect)} "
                                                                  f"{r.effect_size:.2f}",
                     split, "" if i2 is None or not math.isfinite(i2) else f"{i2:.2f}", need, c.note])
    return header, body


_TEST_NAMES = {"welch-t": "Welch t", "paired-t": "paired t", "mann-whitney-u": "Mann-Whitney U",
               "wilcoxon": "Wilcoxon", "fisher-exact": "Fisher exact", "problem-t": "t over problems",
               "problem-wilcoxon": "Wilcoxon over problems", "problem-sign": "sign test over problems"}
_EFFECT_NAMES = {"hedges-g": "g", "cohen-dz": "d_z", "risk-difference": "RD", "problem-dz": "d (problems)"}


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return "< 0.001" if p < 0.001 else f"{p:.3g}"


def _cell_runs(mine: list[dict[str, Any]], total: int) -> str:
    return f"{len(mine)} of {total}"


def summary_tables(data: StudyData, outcomes: Optional[list[OutcomeSummary]] = None,
                   comparisons: Optional[Comparisons] = None) -> list[tuple[str, list[str], list[list[str]]]]:
    """The summary as (title, header, rows) tables of strings: outcomes, comparisons, means, planned paths,
    direct comparison, per problem."""
    outcomes = outcomes if outcomes is not None else data.outcomes()
    done = [r for r in data.rows if r.get("status") == "completed"]
    modes = data.modes
    configs = data.configurations
    tables = [("Outcomes per configuration and mode (success rate with its Wilson 95% interval over the counted "
               "runs: completed or failed; a testbed error is not the planner's)", *outcome_rows(outcomes))]
    if comparisons is not None and len(comparisons):
        per_problem = sum(not c.pooled for c in comparisons)
        shown = per_problem <= MAX_PROBLEM_ROWS or per_problem == len(comparisons)
        tables.append(("Comparisons: every pair, per mode and metric — over all problems (one observation per "
                       "problem, t interval over problems; only with 3 or more problems) and "
                       + ("on each problem (difference a − b, bootstrap 95% CI over its repetitions)" if shown else
                          f"(the {per_problem} comparisons on each problem: comparisons.csv)")
                       + "; Holm-adjusted p per metric and level", *comparison_rows(comparisons, shown)))
    if data.spec.fleet:
        return tables + fleet_tables(data)
    header = ["configuration", "mode", "completed"] + [h for _, h in SUMMARY_METRICS]
    body = []
    for p in configs:
        for m in modes:
            mine = [r for r in done if r["configuration"] == p and r["mode"] == m]
            total = sum(1 for r in data.rows if r["configuration"] == p and r["mode"] == m)
            if not mine:
                body.append([p, m, _cell_runs(mine, total)] + ["no completed run"] + [""] * (len(SUMMARY_METRICS) - 1))
                continue
            body.append([p, m, _cell_runs(mine, total)] + [_fmt([r.get(k) for r in mine]) for k, _ in SUMMARY_METRICS])
    tables.append(("Performed paths per configuration and mode: mean ± std over the completed runs (column "
                   "'completed': over how many of the runs); failed runs' metrics are in runs.csv, flagged by "
                   "their outcome", header, body))
    body = []
    for p in configs:
        # one plan per repetition of an experiment, which both its modes drove (a deterministic planner's are
        # the same path, each timed again)
        planned = list({(r["experiment_id"], r.get("repetition")): r for r in data.rows if r["configuration"] == p
                        and r.get("planned_length_m") is not None}.values())
        times = [r.get("planning_time_s") for r in planned]
        row = [p, str(len(planned))]
        for k, _ in PLANNED_METRICS:
            row.append(_fmt(times) if k == "planning_time_s" else _fmt([r.get(f"planned_{k}") for r in planned]))
        body.append(row)
    tables.append(("Computed (planned) paths per configuration: one plan per experiment and repetition (both "
                   "modes drive it); planning time: the median wall time of the planner call in a warmed worker",
                   ["configuration", "plans"] + [h for _, h in PLANNED_METRICS], body))
    problem_set = planners_per_problem(data)
    if problem_set is not None:
        tables.append(problem_set)
    difficulty = difficulty_table(data)
    if difficulty is not None:
        tables.append(difficulty)
    if data.direct:
        body = [[p, str(sum(d["configuration"] == p for d in data.direct))] +
                [_fmt([d.get(k) for d in data.direct if d["configuration"] == p]) for k, _ in DIRECT_METRICS]
                for p in configs]
        tables.append(("Direct comparison ST: field path against the simulated one, per repetition (pairs of "
                       "completed runs)", ["configuration", "pairs"] + [h for _, h in DIRECT_METRICS], body))
    header = ["environment", "plan", "configuration"] + [f"{k} {m}" for m in modes
                                                         for k in ("outcomes", "length (m)", "mean dev. (m)")]
    body = []
    for e in data.experiments:
        rows = [r for r in data.rows if r["experiment_id"] == e["experiment_id"]] if e["experiment_id"] else []
        cells = []
        for m in modes:
            mine = [r for r in rows if r["mode"] == m]
            ok = [r for r in mine if r.get("status") == "completed"]
            cells += [_outcome_cell(mine, e), _fmt([r.get("length_m") for r in ok]),
                      _fmt([r.get("deviation_mean_m") for r in ok])]
        body.append([e["environment"], e["plan"], e["configuration"]] + cells)
    tables.append(("Per problem (outcomes: successes of runs, then the failures; means over completed runs)",
                   header, body))
    return tables


def _optima(data: StudyData) -> dict[Any, float]:
    """The stored optimum (m) of every experiment of ``data`` that poses a problem of the problem set
    (:func:`planners.problems.stored_optimum`), by experiment id."""
    envs = {}
    for item in data.spec.environments:
        try:
            env = load_environment(item)
        except (InvalidEnvironment, OSError):
            continue
        envs[env.name] = env
    out = {}
    for e in data.experiments:
        env = envs.get(e["environment"])
        if env is not None and e.get("start") is not None and e.get("goal") is not None:
            best = stored_optimum(env, e["start"], e["goal"])
            if best is not None:
                out[e["experiment_id"]] = best
    return out


def planners_per_problem(data: StudyData) -> Optional[tuple[str, list[str], list[list[str]]]]:
    """The planners on each problem of the problem set (``twb study planners``; docs/planners.md): how many
    repetitions found a plan, and the planned paths' length, length / the stored optimum, minimum clearance,
    total turning (AOL × length) and planning time, mean ± std over the plans. None when no experiment poses
    a problem of the set."""
    optima = _optima(data)
    if not optima:
        return None
    body = []
    for e in data.experiments:
        if e["experiment_id"] not in optima:
            continue
        best = optima[e["experiment_id"]]
        plans = list({r.get("repetition"): r for r in data.rows if r["experiment_id"] == e["experiment_id"]
                      and r.get("planned_length_m") is not None}.values())
        lengths = [r["planned_length_m"] for r in plans]
        turning = [r["planned_aol_rad_per_m"] * r["planned_length_m"] for r in plans
                   if r.get("planned_aol_rad_per_m") is not None]
        body.append([e["environment"], e["plan"], e["configuration"], f"{best:.3f}",
                     f"{len(plans)} of {data.spec.repetitions}", _fmt(lengths), _fmt([v / best for v in lengths]),
                     _fmt([r.get("planned_clearance_min_m") for r in plans]), _fmt(turning),
                     _fmt([r.get("planning_time_s") for r in plans])])
    return ("Planners per problem of the problem set: the planned paths (one per repetition; mean ± std over "
            "those found) against the problem's stored optimum, the shortest path keeping 0.065 m from every "
            "block by the exact distance (docs/planners.md)",
            ["environment", "plan", "configuration", "optimum (m)", "planned", "length (m)", "length / optimum",
             "min clearance (m)", "turning (rad)", "planning time (s)"], body)


def _outcome_cell(rows: list[dict[str, Any]], exp: dict[str, Any]) -> str:
    if exp["status"] == "rejected":
        return "rejected"
    ok = sum(r["outcome"] == "success" for r in rows)
    fails: dict[str, int] = {}
    for r in rows:
        if r["outcome"] != "success":
            fails[r["outcome"]] = fails.get(r["outcome"], 0) + 1
    return f"{ok}/{len(rows)}" + ("".join(f", {o} {n}" for o, n in fails.items()))


def _failures(data: StudyData) -> list[str]:
    out = [f"experiment {e['experiment_id'] or '-'} ({e['environment']} {e['plan']} {e['configuration']}): "
           f"{e['status']}: {e['error']}" for e in data.experiments if e["status"] != "completed"]
    for r in data.rows:
        if r.get("status") == "completed":
            continue
        where = (f" at ({r['stopped_at_x']:.2f}, {r['stopped_at_y']:.2f})"
                 if isinstance(r.get("stopped_at_x"), float) and isinstance(r.get("stopped_at_y"), float) else "")
        out.append(f"run {r['run_id']} ({r['configuration']} {r['mode']} #{r['repetition']}): {r['outcome']}{where}: "
                   f"{r.get('error') or ''}")
    return out


# METHOD and FLEET_METHOD (how to read the comparisons) live in planners.compared: the API's comparisons say it too.


def _method(data: StudyData) -> str:
    """How to read the answer: :data:`METHOD`, and :data:`FLEET_METHOD` for a fleet study."""
    return METHOD + (FLEET_METHOD if data.spec.fleet else "")


def _what(data: StudyData) -> str:
    """What the study compares: planners, or planner/controller configurations."""
    return "planner" if data.spec.controllers is None else "configuration"


def which_is_better_markdown(answers: list[Answer], what: str = "planner", method: str = METHOD) -> list[str]:
    """The "Which planner (configuration) is better?" section as Markdown lines."""
    lines = [f"## Which {what} is better?", ""]
    for a in answers:
        lines += [f"**{a.title}:** " + " ".join(a.verdicts), ""]
    for a in answers:
        lines += [f"### {a.title}", ""] + [f"- {f}" for f in a.facts] + [""]
    lines += [f"_{method}_", ""]
    return lines


def summary_markdown(data: StudyData, outcomes: Optional[list[OutcomeSummary]] = None,
                     comparisons: Optional[Comparisons] = None) -> str:
    """``summary.md``: the study, which planner is better (in words), outcomes, comparisons, means per
    configuration x mode, planned paths, direct comparison, per problem, what did not complete."""
    spec = data.spec
    outcomes = outcomes if outcomes is not None else data.outcomes()
    comparisons = comparisons if comparisons is not None else data.compare()
    n_runs = len(data.rows)
    done = sum(r.get("status") == "completed" for r in data.rows)
    lines = [f"# Study `{spec.name}`", ""]
    if spec.description:
        lines += [spec.description, ""]
    jitter = (f"start-pose jitter {spec.jitter['xy_m']:g} m, {spec.jitter['theta_rad']:g} rad (std)"
              if spec.jitter else "no start-pose jitter: repetitions in simulation are identical (deterministic "
                                  "simulation)")
    lines += [f"- environments: {', '.join(spec.environment_names())}; plans: "
              f"{', '.join(dict.fromkeys(e['plan'] for e in data.experiments))}; configurations: "
              f"{', '.join(data.configurations)}",
              f"- {spec.repetitions} repetition(s) x modes {', '.join(spec.modes)}; seed {spec.seed}; field "
              f"{spec.field}; {jitter}",
              f"- {len(data.experiments)} experiments, {n_runs} runs: {done} completed, "
              f"{sum(r.get('status') == 'failed' for r in data.rows)} failed, "
              f"{sum(r.get('status') not in JUDGED for r in data.rows)} not counted"
              + (f"; {sum(e['status'] == 'rejected' for e in data.experiments)} job(s) refused"
                 if any(e["status"] == "rejected" for e in data.experiments) else "")
              + (f"; wall time {data.meta['wall_s']:.1f} s" if data.meta.get("wall_s") is not None else ""),
              "- S = simulation (ideal robot), T = Teleworkbench (emulated field robot, tracker poses), "
              "ST = direct comparison of T against S; units m, rad, s", ""]
    lines += which_is_better_markdown(which_is_better(data, comparisons, outcomes), _what(data), _method(data))
    for title, header, body in summary_tables(data, outcomes, comparisons):
        lines += [f"## {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(row) + " |" for row in body]
        lines.append("")
    fails = _failures(data)
    if fails:
        lines += ["## Not completed", ""] + [f"- {f}" for f in fails] + [""]
    return "\n".join(lines)


def _html_table(header: list[str], body: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    rows = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in body)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"


_CSS = """body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:13px}td,th{border:1px solid #ccc;padding:3px 7px;text-align:right}
th{background:#f3f3f3}td:first-child,td:nth-child(2){text-align:left}img{max-width:100%;border:1px solid #eee}
figure{margin:1.5em 0}figcaption{color:#555;font-size:14px}
section.answer{background:#f6f8fb;border:1px solid #d6dde6;padding:.3em 1.2em 1em;margin:1em 0}
p.verdict{font-size:16px}p.method{color:#555;font-size:13px}"""

_CAPTIONS = {
    "fig5_outcomes": "Outcomes — how the runs of each configuration ended, per mode: success, collision, timeout, "
                     "other failure, not counted; the success rate with its Wilson 95% interval.",
    "fig6_metrics": "Fig. 6 — each metric per configuration: computed path, simulation (S), Teleworkbench (T) and "
                    "the direct comparison (ST); mean ± std over the completed runs (under each group: completed of "
                    "runs per mode); a mode without a completed run says so instead of a bar.",
    "fig7_ratios": "Fig. 7 — performed / planned ratios of length, smoothness and clearance (1 = as planned), over "
                   "the completed runs.",
    "fig8_paths": "Fig. 8 — computed (dashed), simulated (blue) and field (red) paths over each environment; failed "
                  "runs in orange up to where they stopped, ✕ marking the spot; moving obstacles on their exact "
                  "tracks (dotted) over the panel's longest run.",
    "fig9_difficulty": "Success against difficulty — each world's success rate (counted runs) against each of its "
                       "difficulty metrics, a series per configuration and mode (field filled, simulation hollow); "
                       "Spearman's rho over the worlds in the legend.",
    "fig6_fleet_metrics": "Fleet metrics against the number of robots, per environment: the share of runs in which "
                          "every robot arrived (Wilson 95% interval), the makespan over the completed runs and the "
                          "closest approach of two robots over every measured run (Student-t 95% intervals); a "
                          "line per configuration and mode (field solid, simulation dashed).",
    "fig8_fleet_paths": "Every robot of a fleet's run, each in its colour: planned (dashed) and driven (solid) paths, "
                        "start ○, goal ☆, ✕ where a robot that did not arrive stopped, the moving obstacles "
                        "where the tracker saw a field run's obstacle robots (dash-dot), else their exact tracks "
                        "(dotted); the first run per configuration and mode.",
}


def which_is_better_html(answers: list[Answer], what: str = "planner", method: str = METHOD) -> str:
    """The "Which planner is better?" section as HTML."""
    parts = [f"<section class='answer' id='which-is-better'><h2>Which {what} is better?</h2>"]
    for a in answers:
        parts.append(f"<p class='verdict'><strong>{html.escape(a.title)}:</strong> "
                     f"{html.escape(' '.join(a.verdicts))}</p>")
    for a in answers:
        parts.append(f"<h3>{html.escape(a.title)}</h3><ul>" +
                     "".join(f"<li>{html.escape(f)}</li>" for f in a.facts) + "</ul>")
    parts.append(f"<p class='method'>{html.escape(method)}</p></section>")
    return "".join(parts)


def _tracked_obstacles(data: StudyData) -> bool:
    """Whether the study can have kept field runs' obstacle robots (``obstacles/``)."""
    return "twb" in data.modes and any(e.get("moving_obstacles") for e in data.environments.values())


def report_html(data: StudyData, figure_names: list[str], outcomes: Optional[list[OutcomeSummary]] = None,
                comparisons: Optional[Comparisons] = None) -> str:
    """``report.html``: which planner is better, the figures (linked PNG, with the SVG beside) and the tables."""
    spec = data.spec
    outcomes = outcomes if outcomes is not None else data.outcomes()
    comparisons = comparisons if comparisons is not None else data.compare()
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>Study {html.escape(spec.name)}</title>"
             f"<style>{_CSS}</style></head><body><h1>Teleworkbench study <code>{html.escape(spec.name)}</code></h1>"]
    if spec.description:
        parts.append(f"<p>{html.escape(spec.description)}</p>")
    done = sum(r.get("status") == "completed" for r in data.rows)
    failed = sum(r.get("status") == "failed" for r in data.rows)
    parts.append(f"<p>{len(data.experiments)} experiments, {len(data.rows)} runs: {done} completed, {failed} failed. "
                 "Data: <a href='runs.csv'>runs.csv</a> (one row per run: outcome, every metric), "
                 "<a href='outcomes.csv'>outcomes.csv</a>, <a href='comparisons.csv'>comparisons.csv</a>, "
                 "<a href='direct.csv'>direct.csv</a>, " + (
                     "<a href='fleet_outcomes.csv'>fleet_outcomes.csv</a>, <a href='fleet.csv'>fleet.csv</a>, "
                     if spec.fleet else "") + "<a href='summary.md'>summary.md</a>, "
                 "<a href='study.json'>study.json</a>, poses in <code>poses/</code>" + (
                     ", the field runs' obstacle robots as the tracker saw them in <code>obstacles/</code>"
                     if _tracked_obstacles(data) else "") + ".</p>")
    parts.append(which_is_better_html(which_is_better(data, comparisons, outcomes), _what(data), _method(data)))
    for name in figure_names:
        parts.append(f"<figure><a href='{name}.svg'><img src='{name}.png' alt='{name}'></a>"
                     f"<figcaption>{html.escape(_CAPTIONS.get(name, name))} (<a href='{name}.svg'>SVG</a>)"
                     "</figcaption></figure>")
    for title, header, body in summary_tables(data, outcomes, comparisons):
        parts.append(f"<h2>{html.escape(title)}</h2>{_html_table(header, body)}")
    fails = _failures(data)
    if fails:
        parts.append("<h2>Not completed</h2><ul>" + "".join(f"<li>{html.escape(f)}</li>" for f in fails) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(data: StudyData, directory: Optional[Path] = None, dpi: int = 110) -> list[Path]:
    """Write summary.md, outcomes.csv, comparisons.csv, the figures (PNG and SVG) and report.html into
    ``directory`` (default: the study's)."""
    d = Path(directory or data.directory or ".")
    d.mkdir(parents=True, exist_ok=True)
    outcomes, comparisons = data.outcomes(), data.compare()
    write_csv_rows(d / "outcomes.csv", [o.row() for o in outcomes])
    write_csv_rows(d / "comparisons.csv", comparisons.rows(), COMPARISON_COLUMNS)
    (d / "summary.md").write_text(summary_markdown(data, outcomes, comparisons))
    figures = make_figures(data)
    paths = [d / "outcomes.csv", d / "comparisons.csv", d / "summary.md", *save_figures(figures, d, dpi=dpi)]
    if data.spec.fleet:
        paths += write_fleet_csvs(data, d)
    (d / "report.html").write_text(report_html(data, list(figures), outcomes, comparisons))
    paths.append(d / "report.html")
    return paths
