"""Exports of runs and experiments (MCAP, ROS 2 bags): where a download goes and how it is put there.

No network here: :class:`Client` and :class:`AsyncClient` stream the server's
answer into :meth:`ExportTarget.part` and call :meth:`ExportTarget.finish`.
"""

from __future__ import annotations

import os
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional

__all__ = ["ExportFormat", "ExportTarget", "export_target"]

ExportFormat = Literal["mcap", "rosbag2"]
_FORMATS = ("mcap", "rosbag2")


@dataclass(frozen=True)
class ExportTarget:
    """One export's request (``path``, ``params``) and destination: ``out`` is an MCAP file, a zip of a ROS 2
    bag, or (``unzip``) the bag's directory, made from the zip the server sends."""

    path: str
    params: dict[str, str]
    out: Path
    unzip: bool

    @property
    def part(self) -> Path:
        """The file the download is written to before it is complete."""
        return self.out.with_name(self.out.name + ".part")

    def finish(self) -> Path:
        """The complete download in its place: renamed to ``out``, or unpacked into the directory ``out``."""
        if not self.unzip:
            os.replace(self.part, self.out)
            return self.out
        try:
            self.out.mkdir(parents=True)
            with zipfile.ZipFile(self.part) as zf:
                for member in zf.infolist():
                    name = Path(member.filename).name  # the bag's files, flat: never outside ``out``
                    if member.is_dir() or not name:
                        continue
                    with zf.open(member) as src, open(self.out / name, "wb") as dst:
                        shutil.copyfileobj(src, dst)
        finally:
            self.part.unlink(missing_ok=True)
        return self.out


def export_target(api_prefix: str, run_id: Optional[int], experiment_id: Optional[int], format: str,
                  out: Optional[str | os.PathLike[str]]) -> ExportTarget:
    """Where an export of run ``run_id`` or experiment ``experiment_id`` goes (exactly one of them).

    ``out`` defaults to ``run-<id>.mcap`` (``experiment-<id>.mcap``) in the
    current directory for MCAP, and to the bag directory ``run-<id>``
    (``experiment-<id>``) for a ROS 2 bag; a ``.zip`` ``out`` keeps the bag
    zipped as the server sends it.  Raises :class:`ValueError` for a bad
    argument and :class:`FileExistsError` when ``out`` exists already.
    """
    if (run_id is None) == (experiment_id is None):
        raise ValueError("give either `run_id` or `experiment_id` (exactly one)")
    if format not in _FORMATS:
        raise ValueError(f"`format` must be 'mcap' or 'rosbag2', got {format!r}")
    kind, ident = ("runs", int(run_id)) if run_id is not None else ("experiments", int(experiment_id))  # type: ignore[arg-type]
    stem = f"{'run' if kind == 'runs' else 'experiment'}-{ident}"
    if out is None:
        dest = Path(f"{stem}.mcap" if format == "mcap" else stem)
    else:
        dest = Path(out)
    unzip = format == "rosbag2" and dest.suffix.lower() != ".zip"
    if dest.exists():
        raise FileExistsError(f"{dest} exists already; give another `out` or remove it")
    return ExportTarget(f"{api_prefix}/{kind}/{ident}/export", {"format": format}, dest, unzip)
