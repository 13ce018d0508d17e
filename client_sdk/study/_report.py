"""A study's summary (Markdown), figures and HTML report, written from its data."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any, Optional

from ._data import StudyData
from ._figures import make_figures, mean_std, save_figures

__all__ = ["SUMMARY_METRICS", "summary_markdown", "summary_tables", "write_report"]

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
    ("goal_reached", "goal reached"),
    ("collided", "collided"),
)
PLANNED_METRICS = (("length_m", "length (m)"), ("smoothness_rad", "κ' (rad)"), ("clearance_min_m", "min clearance (m)"),
                   ("aol_rad_per_m", "AOL (rad/m)"), ("planning_time_s", "planning time (s)"))
DIRECT_METRICS = (("deviation_mean_m", "mean dev. (m)"), ("deviation_max_m", "max dev. (m)"),
                  ("hausdorff_m", "Hausdorff (m)"), ("frechet_m", "Fréchet (m)"))


def _fmt(values: list[Any], rate: bool = False) -> str:
    if rate:
        vals = [v for v in values if isinstance(v, bool)]
        return f"{sum(vals)}/{len(vals)}" if vals else "–"
    mean, std, n = mean_std(values)
    if mean is None:
        return "–"
    digits = 3 if abs(mean) < 100 else 1
    return f"{mean:.{digits}f}" + (f" ± {std:.{digits}f}" if std is not None else "")


def summary_tables(data: StudyData) -> list[tuple[str, list[str], list[list[str]]]]:
    """The summary as (title, header, rows) tables of "mean ± std" strings."""
    done = [r for r in data.rows if r.get("status") == "completed"]
    modes = list(dict.fromkeys(r["mode"] for r in data.rows)) or list(data.spec.modes)
    tables = []
    header = ["planner", "mode", "runs"] + [h for _, h in SUMMARY_METRICS]
    body = []
    for p in data.planners:
        for m in modes:
            mine = [r for r in done if r["planner"] == p and r["mode"] == m]
            total = sum(1 for r in data.rows if r["planner"] == p and r["mode"] == m)
            body.append([p, m, f"{len(mine)}/{total}"] +
                        [_fmt([r.get(k) for r in mine], rate=k in ("goal_reached", "collided")) for k, _ in SUMMARY_METRICS])
    tables.append(("Performed paths per planner and mode (mean ± std over completed runs)", header, body))
    body = []
    for p in data.planners:
        exps = [e for e in data.experiments if e["planner"] == p]
        planned = {r["experiment_id"]: r for r in done if r["planner"] == p}.values()
        row = [p, str(len(exps))]
        for k, _ in PLANNED_METRICS:
            row.append(_fmt([e.get("planning_time_s") for e in exps]) if k == "planning_time_s"
                       else _fmt([r.get(f"planned_{k}") for r in planned]))
        body.append(row)
    tables.append(("Computed (planned) paths per planner", ["planner", "experiments"] + [h for _, h in PLANNED_METRICS],
                   body))
    if data.direct:
        body = [[p, str(sum(d["planner"] == p for d in data.direct))] +
                [_fmt([d.get(k) for d in data.direct if d["planner"] == p]) for k, _ in DIRECT_METRICS]
                for p in data.planners]
        tables.append(("Direct comparison ST: field path against the simulated one, per repetition",
                        ["planner", "pairs"] + [h for _, h in DIRECT_METRICS], body))
    header = ["environment", "plan", "planner"] + [f"{k} {m}" for m in modes for k in ("length (m)", "mean dev. (m)")]
    body = []
    for e in data.experiments:
        mine = [r for r in done if r["experiment_id"] == e["experiment_id"]] if e["experiment_id"] else []
        body.append([e["environment"], e["plan"], e["planner"]] +
                    [_fmt([r.get(k) for r in mine if r["mode"] == m]) for m in modes
                     for k in ("length_m", "deviation_mean_m")])
    tables.append(("Per problem", header, body))
    return tables


def _failures(data: StudyData) -> list[str]:
    out = [f"experiment {e['experiment_id'] or '-'} ({e['environment']} {e['plan']} {e['planner']}): "
           f"{e['status']}: {e['error']}" for e in data.experiments if e["status"] != "completed"]
    out += [f"run {r['run_id']} ({r['mode']} #{r['repetition']}): {r['status']}: {r.get('error') or ''}"
            for r in data.rows if r.get("status") != "completed"]
    return out


def summary_markdown(data: StudyData) -> str:
    """``summary.md``: the study, mean ± std per planner x mode, planned paths, direct comparison, failures."""
    spec = data.spec
    n_runs = len(data.rows)
    done = sum(r.get("status") == "completed" for r in data.rows)
    lines = [f"# Study `{spec.name}`", ""]
    if spec.description:
        lines += [spec.description, ""]
    lines += [f"- environments: {', '.join(spec.environment_names())}; plans: "
              f"{', '.join(dict.fromkeys(e['plan'] for e in data.experiments))}; planners: {', '.join(data.planners)}",
              f"- {spec.repetitions} repetition(s) x modes {', '.join(spec.modes)}; seed {spec.seed}; field {spec.field}",
              f"- {len(data.experiments)} experiments, {done}/{n_runs} runs completed"
              + (f"; wall time {data.meta['wall_s']:.1f} s" if data.meta.get("wall_s") is not None else ""),
              "- S = simulation (ideal robot), T = Teleworkbench (emulated field robot, tracker poses), "
              "ST = direct comparison of T against S; units m, rad, s", ""]
    for title, header, body in summary_tables(data):
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
figure{margin:1.5em 0}figcaption{color:#555;font-size:14px}"""

_CAPTIONS = {
    "fig6_metrics": "Fig. 6 — each metric per planner: computed path, simulation (S), Teleworkbench (T) and the "
                    "direct comparison (ST); mean ± std.",
    "fig7_ratios": "Fig. 7 — performed / planned ratios of length, smoothness and clearance (1 = as planned).",
    "fig8_paths": "Fig. 8 — computed (dashed), simulated (blue) and field (red) paths over each environment.",
}


def report_html(data: StudyData, figure_names: list[str]) -> str:
    """``report.html``: the summary tables and the figures (linked PNG, with the SVG beside)."""
    spec = data.spec
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>Study {html.escape(spec.name)}</title>"
             f"<style>{_CSS}</style></head><body><h1>Teleworkbench study <code>{html.escape(spec.name)}</code></h1>"]
    if spec.description:
        parts.append(f"<p>{html.escape(spec.description)}</p>")
    done = sum(r.get("status") == "completed" for r in data.rows)
    parts.append(f"<p>{len(data.experiments)} experiments, {done}/{len(data.rows)} runs completed. "
                 "Data: <a href='runs.csv'>runs.csv</a> (one row per run, every metric), "
                 "<a href='direct.csv'>direct.csv</a>, <a href='summary.md'>summary.md</a>, "
                 "<a href='study.json'>study.json</a>, poses in <code>poses/</code>.</p>")
    for name in figure_names:
        parts.append(f"<figure><a href='{name}.svg'><img src='{name}.png' alt='{name}'></a>"
                     f"<figcaption>{html.escape(_CAPTIONS.get(name, name))} (<a href='{name}.svg'>SVG</a>)"
                     "</figcaption></figure>")
    for title, header, body in summary_tables(data):
        parts.append(f"<h2>{html.escape(title)}</h2>{_html_table(header, body)}")
    fails = _failures(data)
    if fails:
        parts.append("<h2>Not completed</h2><ul>" + "".join(f"<li>{html.escape(f)}</li>" for f in fails) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(data: StudyData, directory: Optional[Path] = None, dpi: int = 110) -> list[Path]:
    """Write summary.md, the figures (PNG and SVG) and report.html into ``directory`` (default: the study's)."""
    d = Path(directory or data.directory or ".")
    d.mkdir(parents=True, exist_ok=True)
    (d / "summary.md").write_text(summary_markdown(data))
    figures = make_figures(data)
    paths = [d / "summary.md", *save_figures(figures, d, dpi=dpi)]
    (d / "report.html").write_text(report_html(data, list(figures)))
    paths.append(d / "report.html")
    return paths
