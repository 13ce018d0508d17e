"""``twb study`` (run a study, write its data, summary, figures and report) and ``twb export-ompl``."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Annotated, Iterator, Optional

import typer

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
    spec: Annotated[str, typer.Argument(help="'paper' (the paper's 48 runs) or a study file (JSON; see docs/study.md).")],
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

    OUT gets runs.csv, direct.csv, study.json, poses/, summary.md, fig6/7/8 (PNG, SVG), report.html and the
    paper's findings checked on the study (findings.md, findings.json; also printed).
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
            data = _collect(study_spec, u, tok, progress, timeout)
    else:
        data = _collect(study_spec, url, token, progress, timeout)
    _write(data, out, ompl, progress)
    done = sum(r.get("status") == "completed" for r in data.rows)
    typer.echo(f"study {study_spec.name}: {done}/{len(data.rows)} runs completed in {time.monotonic() - t0:.1f} s; "
               f"report {out / 'report.html'}")
    _print_findings(data, out)


def _collect(spec, url, token, progress, timeout):  # type: ignore[no-untyped-def]
    from client_sdk.study import run_study

    with sdk_client(url, token) as client:
        client.health()
        return run_study(client, spec, progress=progress, timeout=timeout)


def _write(data, out: Path, ompl: Optional[Path], progress: bool) -> None:  # type: ignore[no-untyped-def]
    from client_sdk.study import export_ompl as _export
    from client_sdk.study import write_findings, write_report

    data.save(out)
    if progress:
        typer.echo("writing summary, figures and report...", err=True)
    write_report(data, out)
    write_findings(data, out)
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
