"""A study's results written to disk as its experiments finish, so a study of any size fits in memory.

Each finished experiment's poses go to ``poses/run-<id>.csv`` at once (its
field runs' tracked obstacle robots to ``obstacles/run-<id>.csv``) and its
rows to ``runs.jsonl`` / ``direct.jsonl`` (one JSON object per line); when
the study ends :meth:`StudySink.close` turns those into ``runs.csv`` and
``direct.csv`` (one row at a time) and writes ``study.json``.  Nothing but
the rows' column names is kept in memory while the study runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable, Optional

import numpy as np

from .._models import ObstacleTracks
from ._data import DIRECT_COLUMNS, ID_COLUMNS, StudyData, load_study, write_csv, write_obstacles, write_poses
from ._spec import StudySpec

__all__ = ["StudySink"]


class _Rows:
    """Rows appended as JSON lines; at the end, a CSV with ``first`` then every other key in first-seen order."""

    def __init__(self, part: Path, first: Iterable[str]) -> None:
        self._part = part
        self._columns = dict.fromkeys(first)
        self._file = open(part, "w")
        self.count = 0

    def add(self, rows: Iterable[dict[str, Any]]) -> None:
        for row in rows:
            self._columns.update(dict.fromkeys(row))
            self._file.write(json.dumps(row) + "\n")
            self.count += 1
        self._file.flush()

    def close(self, path: Path) -> None:
        self._file.close()
        with open(self._part) as src:
            write_csv(path, list(self._columns), (json.loads(line) for line in src))
        self._part.unlink()


class StudySink:
    """Where a running study's results go (``directory``, created): see the module docstring."""

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        (self.directory / "poses").mkdir(exist_ok=True)
        self._runs = _Rows(self.directory / "runs.jsonl", ID_COLUMNS)
        self._direct = _Rows(self.directory / "direct.jsonl", DIRECT_COLUMNS)

    @property
    def runs(self) -> int:
        """Run rows written so far."""
        return self._runs.count

    def add(self, rows: list[dict[str, Any]], direct: list[dict[str, Any]], poses: dict[int, np.ndarray],
            obstacles: Optional[dict[int, ObstacleTracks]] = None) -> None:
        """One finished experiment: its run rows, direct-comparison rows, each run's poses and its field runs'
        tracked obstacle robots."""
        for run_id, arr in poses.items():
            write_poses(self.directory / "poses" / f"run-{run_id}.csv", arr)
        for run_id, obs in (obstacles or {}).items():
            write_obstacles(self.directory / "obstacles" / f"run-{run_id}.csv", obs)
        self._runs.add(rows)
        self._direct.add(direct)

    def close(self, spec: StudySpec, environments: dict[str, dict[str, Any]], experiments: list[dict[str, Any]],
              meta: dict[str, Any]) -> StudyData:
        """Write runs.csv, direct.csv and study.json; the study as :func:`load_study` reads it (poses on disk)."""
        self._runs.close(self.directory / "runs.csv")
        self._direct.close(self.directory / "direct.csv")
        doc = {"spec": spec.to_json(), **meta, "environments": environments, "experiments": experiments}
        (self.directory / "study.json").write_text(json.dumps(doc, indent=1) + "\n")
        return load_study(self.directory)
