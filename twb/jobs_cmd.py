"""Job commands over the SDK: ``twb submit``, ``status``, ``wait``, ``results``, ``cancel``, ``envs``.

Each talks to a running testbed (``--url``/``TWB_URL``, ``--token``/``TWB_TOKEN``
or the token file ``twb up`` writes); errors are one line on stderr.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from typer.core import TyperGroup

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client

__all__ = ["cancel", "envs_app", "job_label", "results", "status", "submit", "wait"]

EXIT_NOT_COMPLETED = 1


def _read_job_file(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        fail(f"cannot read job file {path}: {exc.strerror or exc}")
    except json.JSONDecodeError as exc:
        fail(f"{path}: invalid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}")
    if not isinstance(data, dict):
        fail(f"{path}: a job file is a JSON object such as {{\"environment\": \"room\", \"start\": [...], ...}}")
    return data


def _read_path_file(path: Path) -> list[list[float]]:
    """Points from JSON (a list, or ``{"path": [...]}`` as ``twb plan`` prints) or CSV with x,y[,theta] columns."""
    import csv

    try:
        text = path.read_text()
    except OSError as exc:
        fail(f"cannot read path file {path}: {exc.strerror or exc}")
    if text.lstrip().startswith(("[", "{")):
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            fail(f"{path}: invalid JSON: {exc.msg}")
        pts = doc.get("path") if isinstance(doc, dict) else doc
    else:
        rows = list(csv.DictReader(text.splitlines()))
        if not rows or "x" not in rows[0] or "y" not in rows[0]:
            fail(f"{path}: CSV needs a header with x,y[,theta] columns (as `twb plan --format csv` writes)")
        try:
            pts = [[float(r["x"]), float(r["y"])] + ([float(r["theta"])] if r.get("theta") else []) for r in rows]
        except ValueError as exc:
            fail(f"{path}: {exc}")
    if not isinstance(pts, list) or len(pts) < 2:
        fail(f"{path}: a path needs at least 2 points")
    return pts


def submit(
    job_file: Annotated[Optional[Path], typer.Argument(help="JSON job file (fields of POST /api/v1/experiments); flags override it.")] = None,
    env: Annotated[Optional[str], typer.Option("--env", help="Environment name (room, blocks, or one you created), or an environment file (JSON): created on the testbed if needed.")] = None,
    plan: Annotated[Optional[str], typer.Option("--plan", help="The environment's named start/goal pair (e.g. A).")] = None,
    start: Annotated[Optional[str], typer.Option(help="Start X,Y[,A]: metres; A in radians or e.g. 90deg.")] = None,
    goal: Annotated[Optional[str], typer.Option(help="Goal X,Y[,A]: metres; A in radians or e.g. 90deg.")] = None,
    planner: Annotated[Optional[str], typer.Option(help="fmm, fm2, prm, astar or a plug-in (server default: fmm).")] = None,
    param: Annotated[Optional[list[str]], typer.Option("--param", "-p", help="Planner parameter NAME=VALUE (repeatable).")] = None,
    path: Annotated[Optional[Path], typer.Option("--path", help="Send this path instead of planning: JSON or CSV x,y[,theta] (m, rad).")] = None,
    program: Annotated[Optional[int], typer.Option("--program", help="Plan with your uploaded program of this id (see twb upload).", min=1)] = None,
    modes: Annotated[Optional[str], typer.Option(help="sim, twb or sim,twb (default: sim,twb).")] = None,
    repetitions: Annotated[Optional[int], typer.Option(help="Runs per mode (default: 1).", min=1)] = None,
    seed: Annotated[Optional[int], typer.Option(help="Seed of the job (planner sampling, noise) (default: 0).", min=0)] = None,
    field: Annotated[Optional[str], typer.Option(help="sub (a 1.8 m sub-field) or full (3.6 m field) (default: sub).")] = None,
    controller: Annotated[Optional[str], typer.Option("--controller", help="The robots' path-tracking controller: schema (default), pure_pursuit, regulated_pure_pursuit, kanayama or a plug-in (docs/controllers.md).")] = None,
    controller_param: Annotated[Optional[list[str]], typer.Option("--controller-param", help="Controller parameter NAME=VALUE, SI units as the name says (repeatable).")] = None,
    controller_program: Annotated[Optional[int], typer.Option("--controller-program", help="Drive the robots with your uploaded controller program of this id (see twb upload; docs/controllers.md).", min=1)] = None,
    wait_: Annotated[bool, typer.Option("--wait", help="Wait for the end (a progress bar, or status lines when not a terminal); exit 1 unless completed.")] = False,
    timeout: Annotated[Optional[float], typer.Option(help="With --wait: give up after this many seconds (exit 3).")] = None,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Submit a job; prints the experiment id (with --wait, waits and prints its final status)."""
    from .plan_cmd import _params
    from .poses import parse_cli_pose

    job = _read_job_file(job_file) if job_file else {}
    fields: dict[str, Any] = {}
    if env:
        fields["environment"] = env
    if start:
        fields["start"] = parse_cli_pose(start, "start")
    if goal:
        fields["goal"] = parse_cli_pose(goal, "goal")
    if planner:
        fields["planner"] = planner
    if param:
        fields["planner_params"] = _params(param)
    if controller:
        fields["controller"] = controller
    if controller_param:
        fields["controller_params"] = _params(controller_param, "--controller-param")
    if path:
        fields["path"] = _read_path_file(path)
    if program is not None:
        fields["program"] = program
    if controller_program is not None:
        fields["controller_program"] = controller_program
    if modes:
        fields["modes"] = [m.strip() for m in modes.split(",") if m.strip()]
    for key, value in (("repetitions", repetitions), ("seed", seed), ("field", field)):
        if value is not None:
            fields[key] = value
    body = {**job, **fields}
    if "environment" not in body:
        fail("give --env NAME (or a job file with an \"environment\")")
    with sdk_client(url, token) as client:
        if env and Path(env).is_file():
            body["environment"] = _environment_from_file(client, Path(env))
        if plan:
            if "start" in body or "goal" in body:
                fail("give either --plan or --start/--goal, not both")
            try:
                p = client.get_environment(body["environment"]).plan(plan)
            except KeyError as exc:
                fail(str(exc.args[0]))
            body.update(start=p.start, goal=p.goal)
        exp = client.submit(body)
        typer.echo(exp.id)
        if wait_:
            sys.stdout.flush()
            done = client.wait(exp.id, timeout=timeout, progress=True)
            _final_line(done)


def load_environment_file(path: Path) -> Any:
    """The environment in ``path``, checked with the planners' model (a clear one-line error otherwise)."""
    from planners import load_environment

    if not path.is_file():
        fail(f"no such environment file: {path}")
    return load_environment(path)


def _environment_from_file(client: Any, path: Path) -> str:
    """Make sure the testbed has the environment of ``path`` (created, or an identical one reused); its name."""
    from client_sdk import Conflict

    env = load_environment_file(path)
    try:
        remote, created = client.ensure_environment(env.to_dict())
    except Conflict as exc:
        fail(f"{path}: {exc.detail}")
    what = "created environment" if created else "using the testbed's identical environment"
    typer.echo(f"{what} {remote.name!r} from {path}", err=True)
    return remote.name


def _final_line(exp: Any) -> None:
    msg = f"experiment {exp.id}: {exp.status} ({sum(r.status == 'completed' for r in exp.runs)}/{len(exp.runs)} runs completed)"
    if exp.status != "completed":
        typer.echo(msg + (f": {exp.error}" if exp.error else ""), err=True)
        raise typer.Exit(EXIT_NOT_COMPLETED)
    typer.echo(msg, err=True)


def job_label(exp: Any) -> str:
    """Where a job's path comes from: ``"fm2"``, ``"program #7"`` or ``"explicit path"``."""
    if getattr(exp, "program", None) is not None:
        return f"program #{exp.program}"
    return exp.planner or "explicit path"


def _num(v: Any, digits: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def status(
    experiment_id: Annotated[Optional[int], typer.Argument(help="Experiment id; without it, list your experiments.")] = None,
    state: Annotated[Optional[str], typer.Option("--status", help="List only experiments in this state.")] = None,
    limit: Annotated[int, typer.Option(help="How many experiments to list.", min=1, max=500)] = 20,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    wide: Annotated[bool, typer.Option("--wide", help="Every column, however wide the terminal.")] = False,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Show one experiment (status, runs) or list your latest experiments."""
    import dataclasses

    with sdk_client(url, token) as client:
        if experiment_id is None:
            page = client.list_experiments(status=state, limit=limit)
            if as_json:
                typer.echo(json.dumps({"data": [_jsonable(dataclasses.asdict(e)) for e in page.data],
                                       "count": page.count}))
                return
            _print_experiment_list(page, wide)
            return
        exp = client.get_experiment(experiment_id)
    if as_json:
        typer.echo(json.dumps(_jsonable(dataclasses.asdict(exp))))
        return
    _print_experiment(exp, wide)


def clip(text: str, limit: int, wide: bool) -> str:
    """``text`` for a table cell: whole with ``wide``, else at most ``limit`` characters, cut after a whole word
    with an ellipsis (never mid-word)."""
    text = " ".join(text.split())
    if wide or len(text) <= limit:
        return text
    cut = text[:limit].rsplit(" ", 1)[0] if " " in text[:limit] else text[:limit - 1]
    return cut.rstrip(",;:") + "…"


def _print_experiment_list(page: Any, wide: bool) -> None:
    from rich.table import Table

    from .tables import console, print_fitted

    rows = [{"id": str(e.id), "status": e.status, "environment": e.environment, "planner": job_label(e),
             "modes": ",".join(e.modes), "reps": str(e.repetitions),
             "created": e.created_at.strftime("%Y-%m-%d %H:%M:%S") if e.created_at else "", "error": clip(e.error, 60, wide)}
            for e in page.data]

    def build(cols: list[str]) -> Table:
        table = Table(*cols, title=f"{len(page.data)} of {page.count} experiments")
        for r in rows:
            table.add_row(*(r[c] for c in cols))
        return table

    columns = [c for c in _LIST_COLUMNS if c != "error" or any(e.error for e in page.data)]
    print_fitted(console(wide), build, columns, ("created", "reps", "modes"), wide)


_LIST_COLUMNS = ("id", "status", "environment", "planner", "modes", "reps", "created", "error")
_RUN_COLUMNS = ("run", "mode", "rep", "status", "robot", "sub-field", "length (m)", "time (s)", "mean dev. (m)", "error")
#: a run's three numbers in `twb status`: (metric, digits) for one robot, and for a multi-robot job's fleet
_RUN_NUMBERS = (("length_m", 3), ("execution_time_s", 2), ("deviation_mean_m", 4))
_FLEET_RUN_COLUMNS = ("run", "mode", "rep", "status", "robot", "sub-field", "success", "makespan (s)",
                      "min robot dist. (m)", "error")
_FLEET_RUN_NUMBERS = (("success_rate", 2), ("makespan_s", 2), ("robot_distance_min_m", 4))


def _is_fleet(exp: Any) -> bool:
    """A multi-robot job (its robots given instead of a start and goal)."""
    return getattr(exp, "robots", None) is not None


def _print_experiment(exp: Any, wide: bool) -> None:
    from rich.table import Table

    from .tables import console, print_fitted

    con = console(wide)
    length = None
    if exp.planned_path is not None and len(exp.planned_path) > 1:
        import numpy as np

        length = float(np.hypot(*np.diff(exp.planned_path[:, :2], axis=0).T).sum())
    source = job_label(exp) if exp.planner is None else f"planner {exp.planner}"
    fleet = _is_fleet(exp)
    where = (f"{len(exp.robots)} robots, robot 0 {_pose(exp.start)} -> {_pose(exp.goal)}" if fleet
             else f"{_pose(exp.start)} -> {_pose(exp.goal)}")
    if exp.controller != "schema":
        source += f", controller {exp.controller}"
    if getattr(exp, "controller_program", None) is not None:
        source += f", controller program #{exp.controller_program}"
    planned = f"planned {_num(length)} m" + (" (robot 0)" if fleet else "")
    con.print(f"experiment {exp.id}: [bold]{exp.status}[/bold]  {exp.environment} {where}  {source}  "
              f"{planned} in {_num(exp.planning_time_s, 4)} s  seed {exp.seed}", highlight=False)
    if exp.error:
        con.print(f"error: {exp.error}", highlight=False)
    names, numbers = (_FLEET_RUN_COLUMNS, _FLEET_RUN_NUMBERS) if fleet else (_RUN_COLUMNS, _RUN_NUMBERS)
    rows = []
    for r in exp.runs:
        m = r.metrics
        rows.append(dict(zip(names, (
            str(r.id), r.mode, str(r.repetition), r.status, r.robot_id or "", _num(r.subfield),
            *(_num(m.get(k), digits) for k, digits in numbers), clip(r.error, 50, wide)))))

    def build(cols: list[str]) -> Table:
        table = Table(*cols)
        for row in rows:
            table.add_row(*(row[c] for c in cols))
        return table

    columns = [c for c in names if c != "error" or any(r.error for r in exp.runs)]
    print_fitted(con, build, columns, (*reversed(names[6:9]), "sub-field"), wide)


def _pose(p: list[float]) -> str:
    return "(" + ", ".join(f"{v:.3g}" for v in p) + ")"


def _jsonable(v: Any) -> Any:
    import datetime

    import numpy as np

    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, datetime.datetime):
        return v.isoformat()
    return v


def wait(
    experiment_id: Annotated[int, typer.Argument(help="Experiment id.")],
    timeout: Annotated[Optional[float], typer.Option(help="Give up after this many seconds (exit 3).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar or status lines.")] = False,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Wait for an experiment to finish (progress on stderr: a bar, or status lines when not a terminal);
    exit 1 unless it completed."""
    with sdk_client(url, token) as client:
        exp = client.wait(experiment_id, timeout=timeout, progress=not quiet)
    _final_line(exp)


RESULT_COLUMNS = (
    ("length_m", "length (m)"), ("smoothness_rad", "κ' (rad)"), ("clearance_min_m", "min clear. (m)"),
    ("execution_time_s", "time (s)"), ("average_speed_m_s", "speed (m/s)"), ("deviation_mean_m", "mean dev. (m)"),
    ("deviation_max_m", "max dev. (m)"), ("length_ratio", "length ratio"), ("goal_reached", "goal"),
    ("collided", "collided"), ("planning_time_s", "plan time (s)"),
)
#: the fleet's metrics of a multi-robot job's runs (docs/metrics.md, "Several robots")
FLEET_RESULT_COLUMNS = (
    ("success_rate", "success"), ("makespan_s", "makespan (s)"), ("robot_distance_min_m", "min robot dist. (m)"),
    ("collisions_robot", "robot coll."), ("collisions_static", "static coll."), ("collisions_moving", "moving coll."),
    ("deadlock", "deadlock"), ("time_sum_s", "flowtime (s)"), ("path_length_sum_m", "length sum (m)"),
    ("safety_time_s", "safety time (s)"),
)


def metrics_json(m: Any) -> dict[str, Any]:
    """The metrics document in the server's shape (``GET /experiments/{id}/metrics``)."""
    import dataclasses

    return {"experiment_id": m.experiment_id, "status": m.status, "planned": m.planned,
            "runs": [dataclasses.asdict(r) for r in m.runs],
            "aggregates": {k: dataclasses.asdict(a) for k, a in m.aggregates.items()},
            "direct": [{"repetition": d.repetition, "sim_run_id": d.sim_run_id, "twb_run_id": d.twb_run_id,
                        **d.metrics} for d in m.direct]}


def results(
    experiment_ids: Annotated[list[int], typer.Argument(help="Experiment id; several: compare them (configurations in this order).")],
    fmt: Annotated[Optional[str], typer.Option("--format", help="table (default), csv or json. One experiment: its metrics per run (csv) or the server's metrics JSON; several: the comparisons' rows (csv, as a study's comparisons.csv) or GET /api/v1/comparisons (json).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="One experiment: print the metrics JSON (server's shape); same as --format json.")] = False,
    as_csv: Annotated[bool, typer.Option("--csv", help="One experiment: print CSV, one row per run, every metric; same as --format csv.")] = False,
    metrics: Annotated[Optional[str], typer.Option("--metrics", help="Several experiments: the metrics to compare after the success rate, comma-separated (default: a study's).")] = None,
    wide: Annotated[bool, typer.Option("--wide", help="Every column, however wide the terminal.")] = False,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Results of an experiment (metrics per run, mean ± std per mode, direct sim-vs-twb comparison), or of
    several compared (outcomes per configuration, then the comparisons: over problems first, then each
    problem's; docs/study.md, "Comparisons").

    Each experiment is its label (the configuration) on its problem. The table fits the terminal: the less
    important columns are left out (and named) when it is narrow; --wide shows every one.
    """
    if sum([as_json, as_csv, fmt is not None]) > 1:
        fail("give one of --format, --json or --csv")
    fmt = "json" if as_json else "csv" if as_csv else (fmt or "table")
    if fmt not in ("table", "csv", "json"):
        fail(f"--format must be table, csv or json, got {fmt!r}")
    if len(experiment_ids) > 1:
        if metrics is not None and not metrics.strip():
            fail("--metrics: give metric names such as length_m,execution_time_s")
        with sdk_client(url, token) as client:
            report = client.compare(experiment_ids, metrics=metrics.split(",") if metrics else None)
        _print_comparison(report, fmt, wide)
        return
    if metrics is not None:
        fail("--metrics compares several experiments: give two or more ids")
    experiment_id = experiment_ids[0]
    with sdk_client(url, token) as client:
        m = client.get_metrics(experiment_id)
        exp = None if fmt != "table" else client.get_experiment(experiment_id)
    if fmt == "json":
        typer.echo(json.dumps(metrics_json(m)))
        return
    if fmt == "csv":
        _print_results_csv(m)
        return
    _print_results(m, exp, wide)


def _print_comparison(report: Any, fmt: str, wide: bool) -> None:
    """Several experiments compared: CSV rows (a study's comparisons.csv), the report as JSON, or tables."""
    if fmt == "csv":
        from client_sdk.study._data import write_csv_stream

        from client_sdk import ComparisonRow

        write_csv_stream(sys.stdout, list(ComparisonRow.COLUMNS), report.table())
        return
    if fmt == "json":
        import dataclasses

        typer.echo(json.dumps(dataclasses.asdict(report)))
        return
    from .tables import console

    con = console(wide)
    names = ", ".join(f"#{e.id} {e.configuration} on {e.problem}" for e in report.experiments)
    con.print(f"comparing {len(report.configurations)} configurations on {len(report.problems)} problem(s): {names}",
              highlight=False)
    _print_outcomes(con, report, wide)
    pooled = report.pooled()
    if pooled:
        _print_rows(con, f"over {len(report.problems)} problems (each problem one observation)", pooled, wide,
                    pooled=True)
    else:
        con.print(f"No verdict over problems: {len(report.problems)} problem(s), at least {report.min_problems} are "
                  "needed; each problem's comparisons follow, and one problem's answer says nothing about others.",
                  highlight=False)
    for problem in report.problems:
        rows = report.per_problem(problem)
        if rows:
            _print_rows(con, f"on {problem}", rows, wide, pooled=False)
    con.print(report.method, highlight=False, style="dim")


_OUTCOME_COLUMNS = ("configuration", "mode", "experiments", "runs", "success", "collision", "timeout", "other",
                    "not counted", "success rate (95% CI)")


def _rate_text(o: Any) -> str:
    """``3/5 (95% CI 23–88 %)`` over the distinct counted runs; identical repetitions say so."""
    s = o.success
    if not o.counted:
        return "no counted run"
    if s.get("rate") is None:
        return f"{s.get('k', 0)}/{s.get('n', 0)}"
    ci = f"{100 * s['ci_low']:.0f}–{100 * s['ci_high']:.0f} %"
    if o.identical:
        return (f"{o.counts.get('success', 0)}/{o.counted} runs; identical repetitions counted once: "
                f"{s['k']}/{s['n']} ({ci})")
    return f"{s['k']}/{s['n']} ({ci})"


def _print_outcomes(con: Any, report: Any, wide: bool) -> None:
    from contract.vocabulary import NOT_COUNTED

    from .tables import print_fitted

    rows = []
    for o in report.outcomes:
        named = ("success", "collision", "timeout")
        rows.append(dict(zip(_OUTCOME_COLUMNS, (
            o.configuration, o.mode, " ".join(f"#{i}" for i in o.experiments), str(o.runs),
            *(str(o.counts.get(k, 0)) for k in named),
            str(sum(n for k, n in o.counts.items() if k not in named and k not in NOT_COUNTED)),
            str(sum(n for k, n in o.counts.items() if k in NOT_COUNTED)), _rate_text(o)))))

    def build(cols: list[str]) -> Any:
        table = compact_table(cols, "outcomes per configuration (success rate over the distinct counted runs)",
                              numeric=("runs", "success", "collision", "timeout", "other", "not counted"))
        for row in rows:
            table.add_row(*(row[c] for c in cols))
        return table

    print_fitted(con, build, list(_OUTCOME_COLUMNS), ("experiments", "not counted", "timeout"), wide)


def _fmt(v: Any) -> str:
    """A comparison's number: 4 significant digits; "–" for none."""
    return "–" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)


def _p(v: Optional[float]) -> str:
    return "–" if v is None else ("< 0.001" if v < 0.001 else f"{v:.3f}")


def _print_rows(con: Any, title: str, rows: list[Any], wide: bool, *, pooled: bool) -> None:
    from .tables import print_fitted

    cols = ["metric", "mode", "a", "b", "mean a", "mean b", "a − b", "95% CI", "test", "p", "Holm p"]
    cols += ["problems a:b", "I²"] if pooled else ["n a:b"]
    cols += ["note"]
    table_rows = []
    for r in rows:
        rate = r.metric == "success_rate"
        val = (lambda v: "–" if v is None else f"{100 * v:+.0f} pt") if rate else _fmt
        mean = (lambda v: "–" if v is None else f"{100 * v:.0f} %") if rate else _fmt
        ci = "–" if r.ci_low is None else f"[{val(r.ci_low)}, {val(r.ci_high)}]"
        cells = {"metric": r.metric, "mode": r.mode, "a": r.a, "b": r.b, "mean a": mean(r.mean_a),
                 "mean b": mean(r.mean_b), "a − b": val(r.diff), "95% CI": ci, "test": r.test or "–", "p": _p(r.p),
                 "Holm p": _p(r.p_holm), "note": r.note}
        if pooled:
            cells["problems a:b"] = f"{r.favour_a}:{r.favour_b} of {r.n_problems}"
            cells["I²"] = "–" if r.heterogeneity_i2 is None else f"{100 * r.heterogeneity_i2:.0f} %"
        else:
            cells["n a:b"] = f"{r.n_a}:{r.n_b}"
        table_rows.append(cells)

    def build(kept: list[str]) -> Any:
        table = compact_table(kept, title, numeric=("mean a", "mean b", "a − b", "95% CI", "p", "Holm p", "I²"))
        if "note" in kept:  # the note wraps rather than widens the table: it says why a number is missing
            table.columns[kept.index("note")].max_width = 44
        for row in table_rows:
            table.add_row(*(row[c] for c in kept))
        return table

    optional = [c for c in ("test", "mean b", "mean a", "I²", "Holm p", "note") if c in cols]
    print_fitted(con, build, cols, optional, wide)


def _print_results_csv(m: Any) -> None:
    import csv

    from client_sdk.study import flat_metrics

    rows = [{"run_id": r.run_id, "mode": r.mode, "repetition": r.repetition, "status": r.status,
             **flat_metrics(r.metrics)} for r in m.runs]
    cols = list(dict.fromkeys(k for r in rows for k in r))
    w = csv.DictWriter(sys.stdout, cols, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)


#: metrics left out first when the terminal is narrow (the last ones here go first)
_RESULT_PRIORITY = ("length_m", "execution_time_s", "deviation_mean_m", "goal_reached", "collided", "length_ratio",
                    "average_speed_m_s", "clearance_min_m", "deviation_max_m", "smoothness_rad", "planning_time_s")
_FLEET_PRIORITY = tuple(k for k, _ in FLEET_RESULT_COLUMNS)


def _result_columns(m: Any) -> tuple[tuple[tuple[str, str], ...], tuple[str, ...]]:
    """The metrics columns of the results table and their priority: the fleet's for a multi-robot job."""
    fleet = any(isinstance(r.metrics.get("robots"), list) for r in m.runs)
    return (FLEET_RESULT_COLUMNS, _FLEET_PRIORITY) if fleet else (RESULT_COLUMNS, _RESULT_PRIORITY)


def compact_table(columns: list[str], title: Optional[str] = None, numeric: tuple[str, ...] = ()) -> Any:
    """A rich table without vertical lines (narrow), numbers right-aligned; headers may hold a line break."""
    from rich import box
    from rich.table import Table

    table = Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True, show_edge=False, pad_edge=False)
    for c in columns:
        table.add_column(c, justify="right" if c in numeric else "left")
    return table


def _header(label: str) -> str:
    """``"length (m)"`` as two lines, ``"length\\n(m)"``: the unit under the name keeps columns narrow."""
    name, sep, unit = label.rpartition(" (")
    return f"{name}\n({unit}" if sep else label.replace(" ", "\n", 1)


def _result_rows(m: Any, metrics: tuple[tuple[str, str], ...] = RESULT_COLUMNS) -> list[tuple[dict[str, str], Optional[str]]]:
    """Rows of the results table: one per run, then mean and std per mode (bold)."""
    rows: list[tuple[dict[str, str], Optional[str]]] = []
    for r in m.runs:
        rows.append(({"run": str(r.run_id), "mode": r.mode, "rep": str(r.repetition), "status": r.status,
                      **{_header(h): _num(r.metrics.get(k), 4 if k == "planning_time_s" else 3)
                         for k, h in metrics}}, None))
    for mode, agg in m.aggregates.items():
        for label, field in (("mean", "mean"), ("± std", "std")):
            cells = {}
            for k, h in metrics:
                s = agg.metrics.get(k)
                v = None if s is None else getattr(s, field)
                cells[_header(h)] = "–" if v is None else f"{v:.{4 if k == 'planning_time_s' else 3}f}"
            rows.append(({"run": label, "mode": mode, "rep": str(agg.runs) if field == "mean" else "", "status": "",
                          **cells}, "bold"))
    return rows


def clock_line(runs: Any) -> str:
    """How the runs' clocks ran: ``clock: lockstep at time scale 5x`` (per run when they differ); '' when none
    recorded it."""
    seen: dict[str, list[int]] = {}
    for r in runs:
        if r.clock is None:
            continue
        scale = "max" if r.time_scale is None else f"{r.time_scale:g}x"
        seen.setdefault(f"{r.clock} at time scale {scale}", []).append(r.id)
    if not seen:
        return ""
    if len(seen) == 1:
        return f"clock: {next(iter(seen))}"
    return "clock: " + "; ".join(f"{k} (runs {', '.join(map(str, ids))})" for k, ids in seen.items())


def _print_plans(con: Any, exp: Any) -> None:
    """A randomised planner's plans, one per repetition (both modes drove it): planner seed, planned length,
    planning wall and CPU time (the median of k calls) and the machine's load then."""
    import math

    seen: dict[int, Any] = {}
    for r in exp.runs:
        if r.repetition not in seen or (seen[r.repetition].planned_path is None and r.planned_path is not None):
            seen[r.repetition] = r
    con.print(f"{exp.planner or 'the program'} is randomised: each repetition planned its own path with its planner "
              "seed (both modes drove it)", highlight=False)
    for rep, r in sorted(seen.items()):
        if r.planned_path is None or not len(r.planned_path):
            con.print(f"  repetition {rep}: seed {r.planner_seed}, no path ({r.error or r.status})", highlight=False)
            continue
        p = r.planned_path
        length = sum(math.dist(a[:2], b[:2]) for a, b in zip(p[:-1], p[1:]))
        timing = "" if r.planning_time_s is None else (
            f", planned in {1000 * r.planning_time_s:.1f} ms"
            + (f" (CPU {1000 * r.planning_cpu_s:.1f} ms)" if r.planning_cpu_s is not None else "")
            + (f", median of {r.planning_repeats}" if (r.planning_repeats or 1) > 1 else "")
            + (f", load {r.planning_load:.2f}" if r.planning_load is not None else ""))
        con.print(f"  repetition {rep}: seed {r.planner_seed}, length {length:.3f} m{timing}", highlight=False)


def _print_results(m: Any, exp: Any, wide: bool) -> None:
    from .tables import console, print_fitted

    con = console(wide)
    metrics, priority = _result_columns(m)
    headers = {k: _header(h) for k, h in metrics}
    rows = _result_rows(m, metrics)
    title = f"experiment {m.experiment_id}: {m.status}" + (f" ({exp.environment}, {job_label(exp)})" if exp else "")

    def build(cols: list[str]) -> Any:
        table = compact_table(cols, title, numeric=tuple(headers.values()))
        for row, style in rows:
            table.add_row(*(row[c] for c in cols), style=style)
        return table

    columns = ["run", "mode", "rep", "status", *headers.values()]
    optional = [headers[k] for k in reversed(priority)]
    print_fitted(con, build, columns, optional, wide)
    stochastic = exp is not None and exp.planner_stochastic
    if exp is not None and (clocks := clock_line(exp.runs)):
        con.print(clocks, highlight=False)
    if m.planned:
        con.print(("planned path (repetition 1): " if stochastic else "planned path: ")
                  + "  ".join(f"{h} {_num(m.planned.get(k))}" for k, h in RESULT_COLUMNS[:3]), highlight=False)
    if stochastic:
        _print_plans(con, exp)
    if m.direct:
        _print_direct(con, m.direct, wide)


_DIRECT_COLUMNS = ("repetition", "sim run", "twb run", "mean dev. (m)", "max dev. (m)", "Hausdorff (m)", "Fréchet (m)")


def _print_direct(con: Any, direct: Any, wide: bool) -> None:
    from .tables import print_fitted

    rows = [dict(zip(_DIRECT_COLUMNS, (str(d.repetition), str(d.sim_run_id), str(d.twb_run_id),
                                       *[_num(d.metrics.get(k), 4) for k in ("deviation_mean_m", "deviation_max_m",
                                                                           "hausdorff_m", "frechet_m")])))
            for d in direct]

    def build(cols: list[str]) -> Any:
        table = compact_table([_header(c) for c in cols], "direct comparison ST (field path against the simulated one)",
                              numeric=tuple(_header(c) for c in _DIRECT_COLUMNS[3:]))
        for row in rows:
            table.add_row(*(row[c] for c in cols))
        return table

    print_fitted(con, build, list(_DIRECT_COLUMNS), ("Fréchet (m)", "max dev. (m)"), wide)


def cancel(
    experiment_ids: Annotated[list[int], typer.Argument(help="Experiment ids (up to 1000 at once).")],
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Cancel experiments: queued runs are dropped, running ones stopped."""
    with sdk_client(url, token) as client:
        if len(experiment_ids) == 1:
            exp = client.cancel(experiment_ids[0])
            typer.echo(f"experiment {exp.id}: {exp.status}")
            return
        result = client.cancel_many(experiment_ids)
    for i in result.cancelled:
        typer.echo(f"experiment {i}: cancelled")
    for i, why in result.not_cancelled.items():
        typer.echo(f"experiment {i}: not cancelled ({why})")
    if result.not_cancelled:
        raise typer.Exit(1)


class _EnvsGroup(TyperGroup):
    """``twb envs NAME`` is ``twb envs show NAME``: a first word that is no sub-command names an environment."""

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        if args and args[0] not in self.commands and not args[0].startswith("-"):
            args = ["show", *args]
        return super().resolve_command(ctx, args)


envs_app = typer.Typer(cls=_EnvsGroup, help="Environments: `twb envs` lists them, `twb envs NAME` prints one as a file, "
                                              "`twb envs create FILE` adds one.")


@envs_app.callback(invoke_without_command=True)
def envs(
    ctx: typer.Context,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """List the environments (built-ins and yours); `twb envs NAME` prints one as JSON,
    `twb envs create FILE` adds one."""
    ctx.obj = (url, token)
    if ctx.invoked_subcommand is not None:
        return
    from rich.table import Table

    from .tables import console

    with sdk_client(url, token) as client:
        page = client.list_environments(limit=1000)
    table = Table("name", "size (m)", "blocks", "plans", "owner", "description")
    for e in page.data:
        plans = ", ".join(f"{p.name}: {_pose(p.start[:2])}->{_pose(p.goal[:2])}" for p in e.plans)
        table.add_row(e.name, "x".join(f"{v:g}" for v in e.size), str(len(e.blocks)), plans,
                      "built-in" if e.builtin else (e.owner or ""), e.description[:50])
    console().print(table)


def _connection(ctx: typer.Context, url: Optional[str], token: Optional[str]) -> tuple[Optional[str], Optional[str]]:
    parent = (ctx.parent.obj if ctx.parent is not None else None) or (None, None)
    return url or parent[0], token or parent[1]


@envs_app.command("show")
def show_environment(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(help="The environment's name.")],
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Print an environment as an environment file (JSON)."""
    with sdk_client(*_connection(ctx, url, token)) as client:
        typer.echo(json.dumps(client.get_environment(name).to_json(), indent=1))


@envs_app.command("create")
def create_environment(
    ctx: typer.Context,
    file: Annotated[Path, typer.Argument(help="Environment file (JSON: name, size, blocks, plans; docs/planners.md).")],
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Add the environment of FILE to the testbed (checked here first; its name must be free)."""
    from client_sdk import Conflict

    env = load_environment_file(file)
    with sdk_client(*_connection(ctx, url, token)) as client:
        try:
            created = client.create_environment(env.to_dict())
        except Conflict:
            fail(f"the name {env.name!r} is taken on the testbed: give the environment in {file} another \"name\" "
                 f"(`twb submit --env {file}` reuses the testbed's if it is identical)")
    plans = ", ".join(p.name for p in created.plans) or "none"
    typer.echo(f"Created environment {created.name!r}: {created.size[0]:g} x {created.size[1]:g} m, "
               f"{len(created.blocks)} blocks, plans: {plans}. Use it: twb submit --env {created.name} ...")
