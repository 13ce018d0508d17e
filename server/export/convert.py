"""One entry point for every format: records in, the export's bytes written to a binary file."""

from __future__ import annotations

from typing import IO, Sequence

from .formats import ExportFormat
from .mcap_file import write_mcap
from .record import RunRecord
from .rosbag2_file import write_rosbag2_zip

__all__ = ["write_export"]


def write_export(records: Sequence[RunRecord], fmt: ExportFormat, out: IO[bytes], *, name: str,
                 experiment: bool = False) -> None:
    """Write ``records`` as ``fmt`` to ``out``: an MCAP file, or a ROS 2 bag directory ``name`` zipped.

    ``experiment``: the runs are an experiment's (topics and frames under ``run_<id>``).
    """
    if fmt is ExportFormat.MCAP:
        write_mcap(records, out, experiment=experiment)
    else:
        write_rosbag2_zip(records, out, name, experiment=experiment)
