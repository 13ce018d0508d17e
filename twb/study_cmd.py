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
def embedded_testbed(data_dir: Path, *, sim_robots: int = 4, timeout: float = 60.0) -> Iterator[tuple[str, str]]:
    """Run ``twb up --time-scale max --port 0`` as a child process; yields (url, token), stops it after."""
    from .launch import LaunchError, LocalTestbed

    try:
        tb = LocalTestbed(data_dir, "--time-scale", "max", "--sim-robots", str(sim_robots), timeout=timeout)
    except LaunchError as exc:
        fail(f"the embedded testbed did not start: {exc}")
    with tb:
        yield tb.url, tb.token


def study(
    spec: Annotated[str, typer.Argument(help="'paper' (the paper's 48 runs), 'noise' (sensor noise and control inaccuracies, 80 field runs), 'controllers' (every built-in controller, 64 runs), 'fleet' (prioritized vs uncoordinated FMM on 2, 4, 8 robots, 72 runs) or a study file (JSON; see docs/study.md).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory (created).")] = Path("study"),
    embedded: Annotated[bool, typer.Option("--embedded", help="Start a testbed of our own (twb up --time-scale max) in OUT/testbed and stop it after.")] = False,
    ompl: Annotated[Optional[Path], typer.Option("--ompl", help="Also write an OMPL benchmark database (Planner Arena) here.")] = None,
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
    _write(data, out, ompl, progress)
    code = _outcome_line(data, study_spec, time.monotonic() - t0, out)
    _print_findings(data, out)
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


def _write(data, out: Path, ompl: Optional[Path], progress: bool) -> None:  # type: ignore[no-untyped-def]
    from client_sdk.study import export_ompl as _export
    from client_sdk.study import write_findings, write_report

    if data.directory is None or data.directory.resolve() != out.resolve():
        data.save(out)  # run_study wrote it there already as the experiments finished
    if progress:
        typer.echo("writing summary, figures and report...", err=True)
    write_report(data, out)
    write_findings(data, out)  # none for a fleet: the paper's findings concern one robot's paths
    if ompl is not None:
        counts = _export(data, ompl)
        if progress:
            typer.echo(f"OMPL database {ompl}: {counts['runs']} runs, {counts['experiments']} experiments", err=True)


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
        verdict = "n/a" if f.held is None else ("[green]held[/]" if f.held else "[red]NOT held[/]")
        table.add_row(str(i), f.claim, f.detail, verdict)
    Console(width=max(Console().width, 120)).print(table)


def export_ompl(
    study_dir: Annotated[Path, typer.Argument(help="A study directory written by `twb study`.")],
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="SQLite file (default: STUDY_DIR/study.db).")] = None,
    report: Annotated[bool, typer.Option("--report", help="Also redraw summary.md, figures, report.html and the findings.")] = False,
) -> None:
    """Export a study to OMPL's benchmark database (SQLite) for Planner Arena; works offline."""
    from client_sdk.study import export_ompl as _export
    from client_sdk.study import load_study, write_report

    data = load_study(study_dir)
    if report:
        from client_sdk.study import write_findings

        write_report(data, study_dir)
        write_findings(data, study_dir)
    path = out or study_dir / "study.db"
    counts = _export(data, path)
    typer.echo(f"{path}: {counts['experiments']} experiments, {counts['plannerConfigs']} planner configurations, "
               f"{counts['runs']} runs, {counts['progress']} progress rows")
