"""A fleet study's tables: how the runs ended by kind and the fleet metrics with their 95% intervals, per
configuration x environment x robot count x mode (summary.md, report.html, fleet_outcomes.csv, fleet.csv)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

from ._data import StudyData, write_csv_rows
from ._fleet_results import FLEET_KINDS, FLEET_METRICS, FleetGroup, fleet_groups

__all__ = ["FLEET_TABLE_METRICS", "fleet_tables", "interval_cell", "write_fleet_csvs"]

#: the columns of the fleet metrics table: (metric, header)
FLEET_TABLE_METRICS = (
    ("makespan_s", "makespan (s)"),
    ("time_sum_s", "flowtime (s)"),
    ("path_length_sum_m", "Σ path length (m)"),
    ("robot_success_rate", "robots arrived (share)"),
    ("robot_distance_min_m", "closest approach (m)"),
    ("safety_time_s", "within safety radius (s)"),
    ("collisions_robot", "robot-robot hits"),
    ("collisions_moving", "moving-obstacle hits"),
    ("collisions_static", "block/wall hits"),
)
_KIND_HEADERS = ("success", "robot-robot", "moving obstacle", "block/wall", "deadlock", "timeout")


def interval_cell(summary: dict[str, Any], decimals: int) -> str:
    """``mean [low, high] (n)`` of a :func:`planners.stats.summarize` result: ``–`` without values, no interval
    for one value, ``identical ×n`` when every value is the same."""
    n, mean = summary.get("n", 0), summary.get("mean")
    if not n or mean is None:
        return "–"
    if n == 1 or summary.get("ci_low") is None:
        return f"{mean:.{decimals}f} (n = 1)"
    if summary.get("std") == 0:
        return f"{mean:.{decimals}f} (identical ×{n})"
    return f"{mean:.{decimals}f} [{summary['ci_low']:.{decimals}f}, {summary['ci_high']:.{decimals}f}] (n = {n})"


def fleet_tables(data: StudyData, groups: Optional[list[FleetGroup]] = None) \
        -> list[tuple[str, list[str], list[list[str]]]]:
    """The fleet tables as (title, header, rows) of strings: outcomes by kind, then the metrics."""
    groups = groups if groups is not None else fleet_groups(data)
    keys = ["configuration", "environment", "robots", "mode"]
    head = keys + ["runs", *_KIND_HEADERS, "other failure", "not counted", "all robots arrived (95% CI)"]
    body = []
    for g in groups:
        other = str(g.count("other")) + (f" ({g.other_detail})" if g.other_detail else "")
        body.append([g.configuration, g.environment, str(g.robots), g.mode, str(g.runs),
                     *[str(g.count(k)) for k in FLEET_KINDS], other, str(g.not_counted),
                     g.rate_text()])
    tables = [("Fleet outcomes per configuration, environment and robot count (a run succeeds when every robot "
               "reached its goal; a failed run counts under its gravest kind: robot-robot collision, moving "
               "obstacle, block or wall, then deadlock, timeout; Wilson 95% interval over the counted runs)",
               head, body)]
    head = keys + [f"{h} [{FLEET_METRICS[m].over}]" for m, h in FLEET_TABLE_METRICS]
    body = [[g.configuration, g.environment, str(g.robots), g.mode] +
            [interval_cell(g.metrics[m], FLEET_METRICS[m].decimals) for m, _ in FLEET_TABLE_METRICS]
            for g in groups]
    tables.append(("Fleet metrics per configuration, environment and robot count: mean [Student-t 95% interval] "
                   "(n runs) over the completed runs [completed] or every measured run, failed ones included "
                   "[measured]; identical repetitions (the deterministic simulation) count once; hits are robots "
                   "per run (docs/metrics.md, \"Several robots\")", head, body))
    return tables


def write_fleet_csvs(data: StudyData, directory: Path, groups: Optional[list[FleetGroup]] = None) -> list[Path]:
    """``fleet_outcomes.csv`` (one row per group: runs by kind, the success rate and its Wilson interval) and
    ``fleet.csv`` (one row per group and metric: n, mean, std, 95% interval, over which runs)."""
    from planners.stats import table_rows

    groups = groups if groups is not None else fleet_groups(data)
    write_csv_rows(directory / "fleet_outcomes.csv", [g.row() for g in groups])
    write_csv_rows(directory / "fleet.csv", table_rows(g.aggregate() for g in groups))
    return [directory / "fleet_outcomes.csv", directory / "fleet.csv"]
