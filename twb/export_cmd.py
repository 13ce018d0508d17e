"""``twb export RUN`` / ``twb export --experiment ID``: a run or an experiment as MCAP (Foxglove) or a ROS 2 bag."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client

__all__ = ["export"]


def export(
    run_id: Annotated[Optional[int], typer.Argument(help="Run id (see `twb status ID`); or give --experiment.",
                                                    show_default=False, min=1)] = None,
    experiment: Annotated[Optional[int], typer.Option("--experiment", "-e", min=1, show_default=False,
                                                      help="Export every run of this experiment instead.")] = None,
    format: Annotated[str, typer.Option("--format", "-f", help="mcap (Foxglove) or rosbag2 (ROS 2 bag).")] = "mcap",
    out: Annotated[Optional[Path], typer.Option("--out", "-o", show_default=False, help=(
        "Where to write it (default run-<id>.mcap, or the bag directory run-<id>; a .zip keeps a bag zipped)."))] = None,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Export a run, or every run of an experiment, for Foxglove (MCAP) or ROS 2 tools (a bag): poses as frame
    transforms and poses, planned and driven paths, blocks and moving obstacles, the protocol log and the
    metrics, on the experiment's clock (docs/exports.md)."""
    if (run_id is None) == (experiment is None):
        fail("give a run id or --experiment ID (one of them)")
    if format not in ("mcap", "rosbag2"):
        fail(f"--format must be mcap or rosbag2, got {format!r}")
    with sdk_client(url, token) as client:
        try:
            path = client.export(run_id, experiment_id=experiment, format=format, out=out)  # type: ignore[arg-type]
        except FileExistsError as exc:
            fail(str(exc))
    what = f"run {run_id}" if run_id is not None else f"experiment {experiment}"
    size = sum(f.stat().st_size for f in path.iterdir()) if path.is_dir() else path.stat().st_size
    shown = "ROS 2 bag" if format == "rosbag2" else "MCAP"
    typer.echo(f"{path}: {what} as {shown}, {size / 1e6:.2f} MB")
