"""``twb metrics``: compare a planned path with an executed one from CSV files (docs/design.md, "Metrics" and "Command line").

File format: CSV with a header naming the columns ``t,x,y,theta`` (any
order; extra columns are ignored).  ``x`` and ``y`` (m) are required on
every line.  ``t`` (s) may be missing or empty on every line (planned
paths); when given it must be on every line, finite and non-decreasing, and
the executed file's ``t`` gives the execution time (last minus first) and
the average speed.  ``theta`` is optional and not used: every metric is
computed from the geometry of the points.  Blank lines and lines starting
with ``#`` are skipped.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from .errors import fail

if TYPE_CHECKING:
    import numpy as np

__all__ = ["metrics", "read_path_csv"]


def read_path_csv(path: str | Path, what: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a ``t,x,y,theta`` CSV file: points ``(N, 2)`` in metres — ``(N, 3)`` with theta (rad) when every
    line gives it — and times ``(N,)`` in s (or None).

    Raises :class:`twb.errors.CliError` with one line naming the file
    (``what``, e.g. ``--planned``), the line and the problem.
    """
    import csv

    import numpy as np

    where = f"{what} {path}"
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            lines = [(i, row) for i, row in enumerate(csv.reader(fh), start=1)
                     if row and any(c.strip() for c in row) and not row[0].lstrip().startswith("#")]
    except FileNotFoundError:
        fail(f"{where}: no such file")
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        fail(f"cannot read {where}: {exc}")
    if not lines:
        fail(f"{where} is empty: expected a header t,x,y,theta and at least 2 points")
    header = [c.strip().lower() for c in lines[0][1]]
    for col in ("x", "y"):
        if col not in header:
            fail(f"{where}: the header has no '{col}' column (expected t,x,y,theta, got {','.join(header)})")
    if len(set(header)) != len(header):
        fail(f"{where}: the header repeats a column ({','.join(header)})")
    rows = lines[1:]
    if len(rows) < 2:
        fail(f"{where} must have at least 2 points, got {len(rows)}")
    for lineno, row in rows:
        if len(row) != len(header):
            fail(f"{where} line {lineno}: {len(row)} fields, the header has {len(header)}")
    xy = np.column_stack([_column(rows, header.index(c), c, where) for c in ("x", "y")])
    if "theta" in header and all(row[header.index("theta")].strip() for _, row in rows):
        xy = np.column_stack([xy, _column(rows, header.index("theta"), "theta", where)])
    t = None
    if "t" in header:
        k = header.index("t")
        empty = np.array([not row[k].strip() for _, row in rows])
        if empty.any() and not empty.all():
            fail(f"{where} line {rows[int(np.argmax(empty))][0]}: t is empty; give t on every line or on none")
        if not empty.any():
            t = _column(rows, k, "t", where)
            back = np.flatnonzero(np.diff(t) < 0)
            if len(back):
                fail(f"{where} line {rows[back[0] + 1][0]}: t goes back in time ({t[back[0] + 1]:g} < {t[back[0]]:g})")
    return xy, t


def _column(rows: list[tuple[int, list[str]]], k: int, name: str, where: str) -> np.ndarray:
    """Column ``k`` as finite floats, or a one-line error naming the first bad line."""
    import numpy as np

    texts = [row[k].strip() for _, row in rows]
    try:
        values = np.array(texts, dtype=float)
    except ValueError:
        values = None
    ok = np.isfinite(values) if values is not None else None
    if values is None or not ok.all():
        for (lineno, _), text in zip(rows, texts):
            try:
                if math.isfinite(float(text)):
                    continue
            except ValueError:
                pass
            fail(f"{where} line {lineno}: {name} must be a finite number, got {text!r}")
    return values


def metrics(
    planned: Annotated[Optional[str], typer.Option("--planned", help="Planned path: CSV t,x,y,theta (t may be empty).")] = None,
    executed: Annotated[Optional[str], typer.Option("--executed", help="Executed (performed) path: CSV t,x,y,theta.")] = None,
    env: Annotated[
        Optional[str], typer.Option("--env", help="Environment (built-in name or JSON file) for clearance and collision.")
    ] = None,
    segments: Annotated[
        Optional[int], typer.Option("--segments", help="Segments m of the smoothness resampling (default: segments of 0.05 m).")
    ] = None,
    samples: Annotated[int, typer.Option("--samples", help="Points n of the deviation/clearance resampling.")] = 200,
    robot_radius: Annotated[
        Optional[float], typer.Option("--robot-radius", help="Robot radius (m) for 'collided' (default: the BeBot profile's).")
    ] = None,
    goal_tolerance: Annotated[
        float, typer.Option("--goal-tolerance", help="Distance (m) from the planned end that counts as goal reached.")
    ] = 0.05,
) -> None:
    """Print the metrics of an executed path against the planned one as JSON (docs/design.md, "Metrics"); with
    times and headings of the executed path, the controller's too (docs/metrics.md, "Controller metrics")."""
    from contract.robot_profile import load_profile
    from planners import load_environment
    from planners.control_metrics import ControlSettings, control_metrics
    from planners.metrics import MetricSettings, run_metrics

    if not planned or not executed:
        fail("--planned FILE and --executed FILE are both required (CSV with header t,x,y,theta)")
    if samples < 2:
        fail(f"--samples must be an integer >= 2, got {samples}")
    if segments is not None and segments < 2:
        fail(f"--segments must be an integer >= 2, got {segments}")
    radius = load_profile()["radius_m"] if robot_radius is None else robot_radius
    for name, value in (("--robot-radius", radius), ("--goal-tolerance", goal_tolerance)):
        if not (math.isfinite(value) and value >= 0):
            fail(f"{name} must be a finite number >= 0 (metres), got {value}")
    p0, _ = read_path_csv(planned, "--planned")
    pr, t = read_path_csv(executed, "--executed")
    environment = load_environment(env) if env is not None else None
    settings = MetricSettings(samples=samples, segments=segments, robot_radius=radius, goal_tolerance=goal_tolerance)
    doc = {
        "environment": environment.name if environment is not None else None,
        **run_metrics(p0, pr, env=environment, t=t, settings=settings),
        "parameters": settings.to_dict(),
    }
    if t is not None and pr.shape[1] == 3:
        control = ControlSettings(collision_radius=load_profile()["collision_radius_m"], goal_tolerance=goal_tolerance,
                                  max_speed=load_profile()["max_speed_m_s"])
        doc.update(control_metrics(p0, pr, t, goal=p0[-1, :2], env=environment, performed_length_m=doc["length_m"],
                                   execution_time_s=doc["execution_time_s"], settings=control))
        doc["parameters"].update(control.to_dict())
    json.dump(doc, sys.stdout, indent=1, allow_nan=False)
    sys.stdout.write("\n")
