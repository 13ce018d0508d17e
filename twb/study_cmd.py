"""``twb study`` (run a study, write its data, summary, figures and report) and ``twb export-ompl``."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Annotated, Iterator, Optional

import typer

from contract.vocabulary import JUDGED

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client

__all__ = ["embedded_testbed", "export_ompl", "study"]


@contextlib.contextmanager
def embedded_testbed(data_dir: Path, *, sim_robots: int = 4, timeout: float = 300.0) -> Iterator[tuple[str, str]]:
    """Run ``twb up --time-scale max --port 0`` as a child process; yields (url, token), stops it after."""
    from .launch import LaunchError, LocalTestbed

    try:
        tb = LocalTestbed(data_dir, "--time-scale", "max", "--sim-robots", str(sim_robots), timeout=timeout)
    except LaunchError as exc:
        fail(f"the embedded testbed did not start: {exc}")
    with tb:
        yield tb.url, tb.token


def study(
    spec: Annotated[str, typer.Argument(help="'paper' (the paper's 48 runs), 'noise' (sensor noise and control inaccuracies, 80 field runs), 'controllers' (every built-in controller, 64 runs), 'predictivity' (FMM, FM², PRM x every built-in controller, sim and field: does the simulation predict the field, 192 runs), 'fleet' (LaCAM vs prioritized vs uncoordinated FMM on 4 to 64 robots on the whole field, 60 runs), 'fleet-discs' (prioritized vs FMM on 2, 4, 8 robots among moving discs, 72 runs), 'planners' (every built-in planner, OMPL's when installed, on the paper's and three hard problems, 3 repetitions, simulation) or a study file (JSON; see docs/study.md).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory (created).")] = Path("study"),
    embedded: Annotated[bool, typer.Option("--embedded", help="Start a testbed of our own (twb up --time-scale max) in OUT/testbed and stop it after.")] = False,
    ompl: Annotated[Optional[Path], typer.Option("--ompl", help="Also write an OMPL benchmark database (Planner Arena) here; an existing one only with --ompl-append or --ompl-replace.")] = None,
    ompl_append: Annotated[bool, typer.Option("--ompl-append", help="Add the study's runs to the existing OMPL database --ompl names (e.g. one OMPL's tools wrote; its runs are kept).")] = False,
    ompl_replace: Annotated[bool, typer.Option("--ompl-replace", help="Overwrite the database --ompl names if it exists.")] = False,
    sim_robots: Annotated[int, typer.Option(help="With --embedded: size of the simulation pool.", min=1, max=64)] = 4,
    seed: Annotated[Optional[int], typer.Option(help="The study's seed (planner sampling, every run's noise); "
                                                     "default: the study file's (paper: 0).", min=0)] = None,
    timeout: Annotated[Optional[float], typer.Option(help="Give up (and cancel) after this many seconds.")] = None,
    progress: Annotated[bool, typer.Option("--progress/--no-progress", help="Progress bar on stderr.")] = True,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Run a study (environments x plans x planners x repetitions x modes) and write its report.

    OUT gets runs.csv, outcomes.csv, comparisons.csv, direct.csv, study.json, poses/, obstacles/ (field runs'
    tracked obstacle robots), summary.md (which planner is better, in words), fig5-8 (PNG, SVG) and report.html.  Exit status: 0 every run was submitted and ended
    completed or failed (a failure is a result); 1 the study ran but jobs were refused, runs ended in a testbed
    error, or nothing ran; 2 the study was refused before it ran (with the reasons).  The paper's findings are checked on the
    study (findings.md, findings.json; also printed), except on fleets.
    """
    import dataclasses

    from client_sdk.study import load_spec

    study_spec = load_spec(spec)  # bad files fail before anything starts
    ompl_mode = _ompl_mode(ompl, ompl_append, ompl_replace, "--ompl-")  # so does a database it would not write
    if seed is not None:
        study_spec = dataclasses.replace(study_spec, seed=seed)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    if embedded:
        if url:
            fail("give either --embedded or --url, not both")
        with embedded_testbed(out / "testbed", sim_robots=sim_robots) as (u, tok):
            if progress:
                typer.echo(f"embedded testbed: {u} (log {out / 'testbed' / 'stdout.log'})", err=True)
            data = _collect(study_spec, u, tok, progress, timeout, out)
    else:
        data = _collect(study_spec, url, token, progress, timeout, out)
    _write(data, out, ompl, ompl_mode, progress)
    code = _outcome_line(data, study_spec, time.monotonic() - t0, out)
    _print_findings(data, out)
    _print_predictivity(data, out)
    _print_difficulty(data, out)
    if code:
        raise typer.Exit(code)


def _outcome_line(data, spec, wall: float, out: Path) -> int:  # type: ignore[no-untyped-def]
    """Print how the study went (each refused job on stderr); the exit status: 0 complete, 1 incomplete."""
    rows = data.rows
    done = sum(r.get("status") == "completed" for r in rows)
    failed: dict[str, int] = {}
    for r in rows:
        if r.get("status") == "failed":
            failed[r.get("outcome") or "failed"] = failed.get(r.get("outcome") or "failed", 0) + 1
    lost = sum(r.get("status") not in JUDGED for r in rows)
    refused = [e for e in data.experiments if e["status"] == "rejected"]
    for e in refused:
        typer.echo(f"twb: refused: {e['environment']} {e['plan']} {e['configuration']}: {e['error']}", err=True)
    expected = len(data.experiments) * spec.runs_per_experiment
    parts = [f"{done}/{expected} runs completed"]
    if failed:
        parts.append(f"{sum(failed.values())} failed ({', '.join(f'{o} {n}' for o, n in sorted(failed.items()))})")
    if lost:
        parts.append(f"{lost} not counted (testbed error, cancelled or interrupted)")
    if refused:
        parts.append(f"{len(refused)} job(s) refused ({len(refused) * spec.runs_per_experiment} runs not submitted)")
    typer.echo(f"study {spec.name}: {', '.join(parts)} in {wall:.1f} s; report {out / 'report.html'}")
    ran = sum(r.get("status") in JUDGED for r in rows)
    if not ran:
        typer.echo("twb: error: nothing ran: no run completed or failed", err=True)
    return 1 if refused or lost or not ran else 0


def _collect(spec, url, token, progress, timeout, out):  # type: ignore[no-untyped-def]
    from client_sdk.study import StudyRefused, run_study

    with sdk_client(url, token) as client:
        client.health()
        try:
            return run_study(client, spec, progress=progress, timeout=timeout, out=out)
        except StudyRefused as exc:
            where = f"study {spec.name!r} refused by the testbed at {client.url}"
            if len(exc.reasons) == 1:
                fail(f"{where}: {exc.reasons[0]}")
            for reason in exc.reasons:
                typer.echo(f"twb: refused: {reason}", err=True)
            fail(f"{where}: nothing was run ({len(exc.reasons)} reasons above)")


def _ompl_mode(db: Optional[Path], append: bool, replace: bool, flag: str = "--") -> str:
    """How to write the OMPL database ``db``: ``create`` (it must not exist), ``append`` or ``replace``."""
    if append and replace:
        fail(f"give either {flag}append or {flag}replace, not both")
    if db is None:
        if append or replace:
            fail(f"{flag}append and {flag}replace need --ompl FILE")
        return "create"
    if db.exists() and not (append or replace):
        fail(f"{db} exists: {flag}append adds the runs to it (its runs are kept), {flag}replace overwrites it")
    if append and db.exists():
        from client_sdk.study._ompl import check_ompl_database

        check_ompl_database(db)  # not OMPL's: refused now, not after the study ran
    return "append" if append else "replace" if replace else "create"


def _print_export(done, progress: bool = True) -> None:  # type: ignore[no-untyped-def]
    """The notes of an OMPL export (names the database lacks, the name it took) on stderr."""
    if progress:
        for note in done.notes:
            typer.echo(f"twb: note: {note}", err=True)


def _write(data, out: Path, ompl: Optional[Path], ompl_mode: str, progress: bool) -> None:  # type: ignore[no-untyped-def]
    from client_sdk.study import export_ompl as _export
    from client_sdk.study import write_findings, write_predictivity, write_report

    if data.directory is None or data.directory.resolve() != out.resolve():
        data.save(out)  # run_study wrote it there already as the experiments finished
    if progress:
        typer.echo("writing summary, figures and report...", err=True)
    write_report(data, out)
    write_findings(data, out)  # none for a fleet: the paper's findings concern one robot's paths
    write_predictivity(data, out)  # with two configurations in both modes (docs/fidelity.md, "Predictivity")
    if ompl is not None:
        done = _export(data, ompl, mode=ompl_mode)  # type: ignore[arg-type]
        _print_export(done, progress)
        if progress:
            typer.echo(f"OMPL database {ompl}: {done['runs']} runs, {done['experiments']} experiments"
                       + (f" added to its {done.runs_before} runs" if done.runs_before else "")
                       + f" (version {done.version!r})", err=True)


def _print_findings(data, out: Path) -> None:  # type: ignore[no-untyped-def]
    """The paper's findings on this study as a table on stdout (when any of them applies)."""
    from rich.console import Console
    from rich.table import Table

    from client_sdk.study import paper_findings

    found = paper_findings(data)
    applicable = [f for f in found if f.held is not None]
    if not applicable:
        return
    held = sum(f.held is True for f in found)
    table = Table(title=f"The paper's findings on this study: {held} of {len(applicable)} held "
                        f"({out / 'findings.md'}; checks: docs/fidelity.md)", title_justify="left")
    for col in ("#", "finding", "numbers", "verdict"):
        table.add_column(col, overflow="fold")
    for i, f in enumerate(found, 1):
        if f.held is not None:  # the others are listed with what they need in findings.md
            table.add_row(str(i), f.claim, f.detail, "[green]held[/]" if f.held else "[red]NOT held[/]")
    console = Console(width=max(Console().width, 120))
    console.print(table)
    if len(applicable) < len(found):
        console.print(f"{len(found) - len(applicable)} more need what this study does not have (both modes, the "
                      f"paper's planners): {out / 'findings.md'}")


def _print_predictivity(data, out: Path) -> None:  # type: ignore[no-untyped-def]
    """The sim-to-field predictivity as a table on stdout (a study with two configurations in both modes)."""
    from rich.console import Console
    from rich.table import Table

    from client_sdk.study import PREDICTIVITY_METRICS, predictivity

    if data.spec.fleet:
        return
    found = predictivity(data)
    if not any(p.pairs for p in found):
        return
    n = max(p.configurations for p in found)
    table = Table(title=f"Sim-to-field predictivity, {n} configurations ({out / 'predictivity.md'}; "
                        "docs/fidelity.md#predictivity)", title_justify="left")
    for col in ("metric", "Spearman ρ", "ρ within problems", "flipped", "pairs"):
        table.add_column(col, overflow="fold")
    for p in found:
        table.add_row(PREDICTIVITY_METRICS.get(p.metric, p.metric),
                      *("–" if v is None else f"{v:.2f}" for v in (p.spearman, p.spearman_within, p.flipped)),
                      str(p.pairs))
    Console(width=max(Console().width, 100)).print(table)


def _print_difficulty(data, out: Path) -> None:  # type: ignore[no-untyped-def]
    """A world set's success against difficulty as a table on stdout (summary.md has it too)."""
    from rich.console import Console
    from rich.table import Table

    from client_sdk.study._worlds import difficulty_table

    found = difficulty_table(data)
    if found is None:
        return
    _, header, body = found
    short = {"distance to obstacle (m)": "dist. (m)", "visibility (m)": "visib. (m)", "dispersion": "disp.",
             "characteristic dimension (m)": "char. dim. (m)", "tortuosity": "tort.", "configuration": "config.",
             "worlds / runs": "worlds/runs", "mean success": "success"}
    header = [short.get(h, h) for h in header]
    ws = data.spec.worlds
    table = Table(title=f"Success against difficulty: Spearman ρ (p) over the {len(ws['worlds'])} worlds of "
                        f"{ws['index']}, split {ws['split']} ({out / 'summary.md'}; fig9_difficulty.png)",
                  title_justify="left")
    for col in header:
        table.add_column(col, overflow="fold")
    for row in body:
        table.add_row(*row)
    Console(width=max(Console().width, 120)).print(table)


def export_ompl(
    study_dir: Annotated[Path, typer.Argument(help="A study directory written by `twb study`.")],
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="SQLite file (default: STUDY_DIR/study.db).")] = None,
    append: Annotated[bool, typer.Option("--append", help="Add the study's runs to an existing OMPL benchmark database (one OMPL's ompl_benchmark_statistics.py wrote, or this command): every run it has is kept, its experiment name and version are used so Planner Arena plots both together.")] = False,
    replace: Annotated[bool, typer.Option("--replace", help="Overwrite the database if it exists.")] = False,
    experiment: Annotated[Optional[list[str]], typer.Option("--experiment", help="Experiment name to write a problem under: NAME (a one-problem study) or PROBLEM=NAME (e.g. room-A=MyProblem; repeat for more). Default: the problem's name (room-A); appending a one-problem study to a database of one experiment, that one's.")] = None,
    version: Annotated[Optional[str], typer.Option("--version", help="The experiments' version field (default: the appended database's, else 'Teleworkbench <version>'); Planner Arena plots one version at a time, e.g. 'OMPL 2.0.1'.")] = None,
    report: Annotated[bool, typer.Option("--report", help="Also redraw summary.md, figures, report.html and the findings.")] = False,
) -> None:
    """Export a study to OMPL's benchmark database (SQLite) for Planner Arena; works offline.

    An existing database is kept: --append adds the study to it, --replace overwrites it; without either the
    command refuses.  Exit status 2 when the database is not OMPL's or the names are ambiguous (nothing written).
    """
    from client_sdk.study import export_ompl as _export
    from client_sdk.study import load_study, write_report

    path = out or study_dir / "study.db"
    mode = _ompl_mode(path, append, replace)
    data = load_study(study_dir)
    if report:
        from client_sdk.study import write_findings, write_predictivity

        write_report(data, study_dir)
        write_findings(data, study_dir)
        write_predictivity(data, study_dir)
    done = _export(data, path, mode=mode, experiment=_experiment_names(experiment), version=version)  # type: ignore[arg-type]
    _print_export(done)
    kept = f" (kept its {done.runs_before} runs)" if done.runs_before else ""
    typer.echo(f"{path}: {done['experiments']} experiments ({', '.join(dict.fromkeys(done.experiments.values()))}), "
               f"{done['plannerConfigs']} planner configurations, {done['runs']} runs added{kept}; "
               f"version {done.version!r}")


def _experiment_names(values: Optional[list[str]]) -> Optional[str | dict[str, str]]:
    """``--experiment`` values: one NAME, or PROBLEM=NAME pairs."""
    if not values:
        return None
    if len(values) == 1 and "=" not in values[0]:
        return values[0]
    names: dict[str, str] = {}
    for v in values:
        problem, sep, name = v.partition("=")
        if not sep or not problem or not name:
            fail(f"--experiment {v!r}: give PROBLEM=NAME (e.g. room-A=MyProblem) when naming several problems")
        names[problem] = name
    return names
