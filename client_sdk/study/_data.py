"""A study's data on disk, and in memory as :class:`StudyData`.

The collector writes, in the output directory:

- ``study.json``: the study file, the server, timings, the environments and
  every experiment (job, status, planned path, run ids);
- ``runs.csv``: one row per run: how it ended (``status``, ``outcome``:
  ``success``, ``collision``, ``timeout``, ...; ``failure``; ``stopped_at_x``,
  ``stopped_at_y`` where a failed run stopped) and every metric (docs/design.md,
  "Metrics"; a failed run's too, flagged by its outcome; ``planned_*`` are the
  run's own planned path's, ``planning_*`` its repetition's planning, ``st_*``
  the direct sim-vs-twb comparison of the run's repetition);
- ``direct.csv``: one row per experiment and repetition with both modes;
- ``poses/run-<id>.csv``: the logged poses ``t,x,y,theta`` of each run (a fleet's run:
  ``t,x,y,theta,robot``, robot by robot);
- ``obstacles/run-<id>.csv``: a field run's obstacle robots as the tracker saw them,
  ``obstacle,t,x,y,theta,radius``, obstacle by obstacle (only runs the server stored them for).

Everything else (summary, figures, report, OMPL database) is computed from
these files, offline.
"""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
from dataclasses import dataclass
from dataclasses import field as _field
from pathlib import Path
from typing import Any, Iterable, Optional, TextIO

import numpy as np

from contract.vocabulary import run_outcome

from .._models import ObstacleTracks
from ._compare import compare
from ._outcomes import outcome_table
from ._spec import StudySpec

__all__ = ["DIRECT_COLUMNS", "ID_COLUMNS", "StudyData", "load_study", "read_csv_rows", "run_outcome", "write_csv",
           "write_csv_rows", "write_csv_stream", "write_obstacles", "write_poses"]

#: leading columns of runs.csv (the metrics follow)
ID_COLUMNS = ("study", "experiment_id", "run_id", "environment", "plan", "planner", "controller", "configuration", "mode",
              "repetition", "seed", "planner_seed", "status", "outcome", "failure", "error", "stopped_at_x", "stopped_at_y", "subfield",
              "robot_id", "t_start", "t_end", "profile")
DIRECT_COLUMNS = ("study", "experiment_id", "environment", "plan", "planner", "controller", "configuration", "repetition",
                  "sim_run_id", "twb_run_id", "profile")
_STRINGS = {"study", "environment", "plan", "planner", "controller", "configuration", "profile", "mode", "status",
            "outcome", "failure", "error",
            "robot_id"}


@dataclass
class StudyData:
    """Everything a study collected: ``rows`` (runs.csv), ``direct`` (direct.csv), experiments, environments."""

    spec: StudySpec
    environments: dict[str, dict[str, Any]]
    experiments: list[dict[str, Any]]
    rows: list[dict[str, Any]]
    direct: list[dict[str, Any]]
    meta: dict[str, Any] = _field(default_factory=dict)
    directory: Optional[Path] = None
    _poses: dict[int, np.ndarray] = _field(default_factory=dict, repr=False)
    _obstacles: dict[int, ObstacleTracks] = _field(default_factory=dict, repr=False)

    def poses(self, run_id: int) -> np.ndarray:
        """``(N, 4)`` t, x, y, theta of a run (s, m, m, rad) -- ``(N, 5)`` with the robot's index last for a fleet's
        run --, from memory or ``poses/run-<id>.csv`` (read each time, not kept: a study of thousands of runs would
        not fit)."""
        if run_id in self._poses:
            return self._poses[run_id]
        if self.directory is None:
            raise KeyError(f"no poses for run {run_id}")
        table = _read_table(self.directory / "poses" / f"run-{run_id}.csv")
        return table if table is not None else np.empty((0, 4))

    def obstacles(self, run_id: int) -> Optional[ObstacleTracks]:
        """A field run's obstacle robots as the tracker saw them (``tracks[k]`` ``(T, 4)`` t, x, y, theta; s, m, m,
        rad; ``radii`` m), from memory or ``obstacles/run-<id>.csv``; None where none were stored (a simulation, a
        field run without moving obstacles or whose obstacle robots the server could not replay, a study written
        before they were kept): the study knows only their exact tracks."""
        if run_id in self._obstacles:
            return self._obstacles[run_id]
        table = _read_table(self.directory / "obstacles" / f"run-{run_id}.csv") if self.directory else None
        return _obstacle_tracks(run_id, table) if table is not None else None

    def add_obstacles(self, run_id: int, obstacles: ObstacleTracks) -> None:
        """Keep a field run's tracked obstacle robots in memory (``exact`` False: see :meth:`obstacles`)."""
        self._obstacles[run_id] = obstacles

    def add_poses(self, run_id: int, poses: np.ndarray) -> None:
        """Keep a run's poses in memory: ``(N, 4)``, or ``(N, 5)`` with the robot's index (a fleet's run)."""
        arr = np.asarray(poses, dtype=float)
        self._poses[run_id] = arr.reshape(-1, 5 if arr.ndim == 2 and arr.shape[1] == 5 else 4)

    def __post_init__(self) -> None:
        # study directories written before configurations and outcomes existed
        for e in self.experiments:
            e.setdefault("configuration", e["planner"])
            e.setdefault("controller", "schema")
        for r in self.rows:
            if not r.get("configuration"):
                r["configuration"] = r.get("planner")
            if not r.get("controller"):
                r["controller"] = "schema"
            if not r.get("outcome"):
                r["outcome"] = run_outcome(r.get("status"), r.get("failure"))
        for d in self.direct:
            if not d.get("configuration"):
                d["configuration"] = d.get("planner")
            if not d.get("controller"):
                d["controller"] = "schema"

    @property
    def planners(self) -> list[str]:
        """The configurations' names in study order (see :attr:`configurations`)."""
        return self.configurations

    @property
    def configurations(self) -> list[str]:
        """The compared configurations (a planner with its parameters, an explicit path), in study order."""
        return list(dict.fromkeys(e["configuration"] for e in self.experiments))

    @property
    def modes(self) -> list[str]:
        return list(self.spec.modes)

    def outcomes(self) -> list[Any]:
        """How the runs of each configuration x mode ended, with the success rate's Wilson interval
        (:class:`~client_sdk.study.OutcomeSummary`)."""
        return outcome_table(self)

    def compare(self, metrics: Optional[Iterable[str]] = None, *, modes: Optional[Iterable[str]] = None,
                confidence: float = 0.95, family: str = "metric", test: str = "t", n_resamples: int = 9999,
                seed: int = 0) -> Any:
        """Every pair of configurations, per mode and metric (and the success rate): the difference with its
        bootstrap interval, the test, Holm's correction and an effect size (:func:`~client_sdk.study.compare`)."""
        return compare(self, metrics, modes=modes, confidence=confidence, family=family, test=test,
                       n_resamples=n_resamples, seed=seed)

    @property
    def problems(self) -> list[tuple[str, str]]:
        """(environment, plan) pairs in study order."""
        return list(dict.fromkeys((e["environment"], e["plan"]) for e in self.experiments))

    def save(self, directory: Path) -> None:
        """Write study.json, runs.csv, direct.csv, poses/ and obstacles/ into ``directory``."""
        directory.mkdir(parents=True, exist_ok=True)
        doc = {"spec": self.spec.to_json(), **self.meta, "environments": self.environments,
               "experiments": self.experiments}
        (directory / "study.json").write_text(json.dumps(doc, indent=1) + "\n")
        write_csv_rows(directory / "runs.csv", self.rows, ID_COLUMNS)
        write_csv_rows(directory / "direct.csv", self.direct, DIRECT_COLUMNS)
        (directory / "poses").mkdir(exist_ok=True)
        for run_id, arr in self._poses.items():
            write_poses(directory / "poses" / f"run-{run_id}.csv", arr)
        for run_id, obs in self._obstacles.items():
            write_obstacles(directory / "obstacles" / f"run-{run_id}.csv", obs)
        if self.directory is not None and self.directory.resolve() != directory.resolve():
            # files still on disk where the study was written (a streamed study keeps none in memory)
            for sub in ("poses", "obstacles"):
                _copy_missing(self.directory / sub, directory / sub)
        self.directory = directory


def _copy_missing(src: Path, dst: Path) -> None:
    """Copy the ``run-*.csv`` files of ``src`` that ``dst`` lacks (``src`` may not exist: an older study)."""
    files = sorted(src.glob("run-*.csv"))
    if files:
        dst.mkdir(exist_ok=True)
    for f in files:
        if not (dst / f.name).exists():
            shutil.copyfile(f, dst / f.name)


def _read_table(path: Path) -> Optional[np.ndarray]:
    """A numeric CSV with a header line as ``(N, columns)`` floats; None where there is no such file."""
    if not path.exists():
        return None
    with open(path) as f:
        columns = len(f.readline().split(","))
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2).reshape(-1, columns)


def _obstacle_tracks(run_id: int, table: np.ndarray) -> ObstacleTracks:
    """An ``obstacles/run-<id>.csv`` table (``obstacle,t,x,y,theta,radius``) as the server's tracked obstacles."""
    index = table[:, 0].astype(int)
    rows = [table[index == k] for k in range(int(index.max()) + 1 if len(index) else 0)]
    # an obstacle the tracker never saw is one row without a pose (write_obstacles); directories written
    # before that have no row for it, so no radius either
    return ObstacleTracks(run_id, False, [r[~np.isnan(r[:, 1]), 1:5] for r in rows],
                          [r[0, 5] if len(r) else math.nan for r in rows])


def write_poses(path: Path, poses: np.ndarray) -> None:
    """``poses`` ``(N, 4)`` t, x, y, theta (s, m, m, rad) as a study's CSV (header ``t,x,y,theta``); a fleet's
    ``(N, 5)`` with the robot's index as a fifth column (header ``t,x,y,theta,robot``)."""
    arr = np.asarray(poses, dtype=float)
    fleet = arr.ndim == 2 and arr.shape[1] == 5
    buf = io.StringIO()
    buf.write("t,x,y,theta,robot\n" if fleet else "t,x,y,theta\n")
    np.savetxt(buf, arr.reshape(-1, 5 if fleet else 4), delimiter=",", fmt=["%.5f"] * 4 + ["%d"] * fleet)
    path.write_text(buf.getvalue())


def write_obstacles(path: Path, obstacles: ObstacleTracks) -> None:
    """A field run's tracked obstacle robots as a study's CSV (``path``'s folder created): header
    ``obstacle,t,x,y,theta,radius``, obstacle by obstacle, each pose ``t,x,y,theta`` (s, m, m, rad) with the
    obstacle's index and radius (m); an obstacle the tracker never saw is one row of its index and radius
    with ``nan`` for t, x, y and theta, so every obstacle keeps its index and its radius."""
    parts = []
    for k, (track, r) in enumerate(zip(obstacles.tracks, obstacles.radii)):
        tr = np.asarray(track, dtype=float).reshape(-1, 4)
        tr = tr if len(tr) else np.full((1, 4), np.nan)
        parts.append(np.column_stack([np.full(len(tr), k), tr, np.full(len(tr), r)]))
    buf = io.StringIO()
    buf.write("obstacle,t,x,y,theta,radius\n")
    np.savetxt(buf, np.concatenate(parts) if parts else np.empty((0, 6)), delimiter=",",
               fmt=["%d"] + ["%.5f"] * 5)
    path.parent.mkdir(exist_ok=True)
    path.write_text(buf.getvalue())


def load_study(directory: str | Path) -> StudyData:
    """Read a study directory written by :func:`~client_sdk.study.run_study`."""
    d = Path(directory)
    path = d / "study.json"
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise ValueError(f"{d} is not a study directory: cannot read {path.name} ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: invalid JSON ({exc.msg})") from None
    spec = StudySpec.from_json(doc["spec"], str(path))
    meta = {k: v for k, v in doc.items() if k not in ("spec", "environments", "experiments")}
    rows = read_csv_rows(d / "runs.csv")
    direct = read_csv_rows(d / "direct.csv") if (d / "direct.csv").exists() else []
    return StudyData(spec, doc["environments"], doc["experiments"], rows, direct, meta, d)


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return str(v)


def _value(key: str, text: str) -> Any:
    if text == "":
        return None
    if key in _STRINGS:
        return text
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def write_csv_rows(path: Path, rows: Iterable[dict[str, Any]], first: Iterable[str] = ()) -> list[str]:
    """Write dict rows as CSV; columns: ``first`` then every other key in first-seen order."""
    rows = list(rows)
    cols = list(first)
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    write_csv(path, cols, rows)
    return cols


def write_csv(path: Path, columns: list[str], rows: Iterable[dict[str, Any]]) -> None:
    """Write dict rows as CSV with these ``columns``, one row at a time (``rows`` may be a generator)."""
    with open(path, "w", newline="") as f:
        write_csv_stream(f, columns, rows)


def write_csv_stream(f: TextIO, columns: list[str], rows: Iterable[dict[str, Any]]) -> None:
    """:func:`write_csv` to an open text stream (``sys.stdout``): the same cells (numbers at full precision,
    None and NaN empty, booleans ``true``/``false``), the same line ends."""
    w = csv.writer(f)
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])


def read_csv_rows(path: Path) -> list[dict[str, Any]]:
    """Rows of a CSV written by :func:`write_csv_rows`, with numbers, booleans and None restored."""
    with open(path, newline="") as f:
        return [{k: _value(k, v) for k, v in row.items()} for row in csv.DictReader(f)]
