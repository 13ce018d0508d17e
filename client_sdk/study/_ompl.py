"""Export of a study to OMPL's benchmark database, the SQLite file Planner Arena plots.

The tables are the ones OMPL's ``ompl_benchmark_statistics.py`` creates from benchmark logs
(``experiments``, ``plannerConfigs``, ``enums``, ``runs`` with one column per run property,
``progress``), with the same column types, so a study can be written into a new database or
appended to one OMPL's tools wrote, and Planner Arena plots twb's planners next to OMPL's.

- one *experiment* row per problem (environment and plan, ``room-A``), or the name of the OMPL
  experiment it is appended to; ``version`` as OMPL writes it (``"<library> <version>"``); Planner
  Arena plots together only the runs of one experiment name and one version;
- one *planner configuration* per configuration and mode (``fmm_sim``, ``fmm_twb``);
- one *run* per testbed run with OMPL's properties in OMPL's sense — ``time`` (planning time, s),
  ``solved`` (the planner found a path), ``status`` (``ompl::base::PlannerStatus``, OMPL's codes),
  ``solution_length``, ``solution_smoothness``, ``solution_clearance``, ``solution_segments`` (the
  planned path's, as ``PathGeometric`` computes them) — and twb's own under ``twb_`` names: how the run
  ended (``twb_outcome``, an enum of its own) and every metric of ``runs.csv`` (``twb_length_m`` is the
  driven path's length, ``twb_smoothness_rad`` twb's κ′, ...);
- *progress* rows (``time``, ``best_cost``: OMPL's progress properties, the curve of Planner Arena's
  progress page) for the runs of an anytime planner: the best path length so far (m) against its
  planning time (s) that the built-in OMPL planners report for each repetition (``study.json``'s
  ``repetition_progress``, from each run's ``planning_progress``); twb's own planners are not anytime
  and have none.
"""

from __future__ import annotations

import json
import math
import re
import sqlite3
from dataclasses import dataclass, field
from datetime import datetime
from enum import IntEnum
from pathlib import Path
from typing import Any, Iterable, Literal, Mapping, Optional

import numpy as np

from contract.vocabulary import JOB_OUTCOMES, NOT_COUNTED, FailureKind, RunStatus

from ._data import ID_COLUMNS, StudyData

__all__ = ["OUTCOME_ENUM", "STATUS_DESCRIPTIONS", "OmplExport", "OmplExportError", "PlannerStatus",
           "check_ompl_database", "export_ompl", "ompl_clearance", "ompl_smoothness", "planner_status"]


class PlannerStatus(IntEnum):
    """``ompl::base::PlannerStatus::StatusType``: the codes of OMPL's ``status`` enum (the value a run's
    ``status`` column holds)."""

    UNKNOWN = 0  # uninitialised: here, the planner's result is not known (the run ended before planning did)
    INVALID_START = 1
    INVALID_GOAL = 2
    UNRECOGNIZED_GOAL_TYPE = 3
    TIMEOUT = 4  # "the planner failed to find a solution" (in its time)
    APPROXIMATE_SOLUTION = 5
    EXACT_SOLUTION = 6
    CRASH = 7
    ABORT = 8  # "the planner did not find a solution for some other reason"
    INFEASIBLE = 9  # "the planner decided that the problem is infeasible"


#: the ``enums`` rows of ``status`` as OMPL's benchmark log declares them (``PlannerStatus::asString()``), except
#: ABORT and INFEASIBLE: ``asString()`` has no case for them and says ``Unknown status``; a database that has
#: that text for them is OMPL's all the same
STATUS_DESCRIPTIONS: tuple[str, ...] = ("Unknown status", "Invalid start", "Invalid goal", "Unrecognized goal type",
                                        "Timeout", "Approximate solution", "Exact solution", "Crash", "Abort",
                                        "Infeasible")
_OMPL_UNKNOWN = "Unknown status"
_UNNAMED = (PlannerStatus.ABORT, PlannerStatus.INFEASIBLE)

#: the ``twb_outcome`` enum: how a run ended (``contract.vocabulary.run_outcome``), in this order
OUTCOME_ENUM: tuple[str, ...] = (*JOB_OUTCOMES, *NOT_COUNTED)
OUTCOME = "twb_outcome"

#: OMPL's tables as ``ompl_benchmark_statistics.py`` creates them (OMPL 2.0.1); its run and progress
#: properties are columns added to ``runs`` and ``progress``
_SCHEMA = """
CREATE TABLE IF NOT EXISTS experiments
    (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512),
    totaltime REAL, timelimit REAL, memorylimit REAL, runcount INTEGER,
    version VARCHAR(128), hostname VARCHAR(1024), cpuinfo TEXT,
    date DATETIME, seed VARCHAR(24), setup TEXT);
CREATE TABLE IF NOT EXISTS plannerConfigs
    (id INTEGER PRIMARY KEY AUTOINCREMENT,
    name VARCHAR(512) NOT NULL, settings TEXT);
CREATE TABLE IF NOT EXISTS enums
    (name VARCHAR(512), value INTEGER, description TEXT,
    PRIMARY KEY (name, value));
CREATE TABLE IF NOT EXISTS runs
    (id INTEGER PRIMARY KEY AUTOINCREMENT, experimentid INTEGER, plannerid INTEGER,
    FOREIGN KEY (experimentid) REFERENCES experiments(id) ON DELETE CASCADE,
    FOREIGN KEY (plannerid) REFERENCES plannerConfigs(id) ON DELETE CASCADE);
CREATE TABLE IF NOT EXISTS progress
    (runid INTEGER, time REAL, PRIMARY KEY (runid, time),
    FOREIGN KEY (runid) REFERENCES runs(id) ON DELETE CASCADE);
"""
#: the columns each table of OMPL's schema has whatever the properties (an appended-to database needs them)
_REQUIRED = {
    "experiments": ("id", "name", "totaltime", "timelimit", "memorylimit", "runcount", "version", "hostname",
                    "cpuinfo", "date", "seed", "setup"),
    "plannerConfigs": ("id", "name", "settings"),
    "enums": ("name", "value", "description"),
    "runs": ("id", "experimentid", "plannerid"),
    "progress": ("runid", "time"),
}

#: OMPL's run properties this export writes, with their types (OMPL's names with ``_`` for spaces)
_OMPL_PROPERTIES = {"time": "REAL", "solved": "BOOLEAN", "status": "ENUM", "approximate_solution": "BOOLEAN",
                    "solution_length": "REAL", "solution_smoothness": "REAL", "solution_clearance": "REAL",
                    "solution_segments": "INTEGER", "correct_solution": "BOOLEAN"}
#: runs.csv's columns that are text, or twb's own bookkeeping of the row, not a run property
_NOT_PROPERTIES = set(ID_COLUMNS) - {"experiment_id", "run_id", "repetition", "seed", "planner_seed", "subfield"}
#: the relative agreement of a run's planned length with the stored path's for that path to be the run's
_SAME_PATH = 1e-5

Mode = Literal["create", "append", "replace"]


class OmplExportError(ValueError):
    """The database cannot be written as asked (it exists, is not OMPL's, or the names are ambiguous)."""


@dataclass
class OmplExport:
    """What :func:`export_ompl` wrote: rows per table, the ``version`` and experiment names used (per problem,
    ``"room-A"``), how many runs the database already held (kept), and notes for the user."""

    path: Path
    version: str
    experiments: dict[str, str]
    rows: dict[str, int]
    runs_before: int = 0
    notes: list[str] = field(default_factory=list)

    def __getitem__(self, table: str) -> int:
        return self.rows[table]


# ------------------------------------------------------------------ OMPL's path quantities


def ompl_smoothness(path: Any) -> float:
    """``PathGeometric::smoothness()`` of a path through ``path``'s points (x, y; a heading column is ignored):
    the sum over the path's interior vertices of ``(2 (π − ∠) / (a + b))²``, where ``a`` and ``b`` are the two
    segments at the vertex and ∠ the angle between them (found from the triangle's third side by the law of
    cosines); a straight path has 0.  A vertex whose triangle is degenerate (a zero-length segment, collinear
    points) adds nothing, as in OMPL.  Depends on how densely the path is sampled, like OMPL's."""
    p = np.asarray(path, dtype=float).reshape(len(path), -1)[:, :2]
    if len(p) < 3:
        return 0.0
    seg = np.hypot(*np.diff(p, axis=0).T)
    a, b = seg[:-1], seg[1:]
    c = np.hypot(*(p[2:] - p[:-2]).T)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = (a * a + b * b - c * c) / (2.0 * a * b)
        ok = (cos > -1.0) & (cos < 1.0)
        k = 2.0 * (math.pi - np.arccos(np.where(ok, cos, 0.0))) / (a + b)
    return float(np.sum(np.where(ok, k * k, 0.0)))


def ompl_clearance(env: Any, path: Any) -> float:
    """``PathGeometric::clearance()`` of a path through ``path``'s points: the mean over its vertices of each
    state's clearance — here the distance (m) from the robot's centre there to the nearest static obstacle
    (blocks and field walls; ``planners.geometry.distance_to_obstacles``), the robot radius not subtracted, as in
    twb's own clearance metrics.  ``env``: a :class:`planners.Environment` or its JSON."""
    from planners import parse_environment
    from planners.environment import Environment
    from planners.geometry import distance_to_obstacles

    environment = env if isinstance(env, Environment) else parse_environment(env)
    p = np.asarray(path, dtype=float).reshape(len(path), -1)[:, :2]
    if len(p) == 0:
        return math.inf
    return float(distance_to_obstacles(environment, p).mean())


# ------------------------------------------------------------------ a run's planner result


def _planned(row: Mapping[str, Any]) -> bool:
    length = row.get("planned_length_m")
    return isinstance(length, (int, float)) and not isinstance(length, bool) and math.isfinite(length)


def planner_status(row: Mapping[str, Any], experiment: Optional[Mapping[str, Any]] = None) -> PlannerStatus:
    """The OMPL status of a run's planning (one row of ``runs.csv``; its experiment's entry in ``study.json``).

    ``EXACT_SOLUTION`` where the planner gave a path (the robot may still have failed to follow it: that is
    ``twb_outcome``); for a run that failed in planning (``failure`` ``planning``): ``INVALID_START`` /
    ``INVALID_GOAL`` (a start or goal outside the field or not free), ``INFEASIBLE`` (the planner found start and
    goal unconnected: separate free regions, unreachable on its grid, the straight segment blocked) or ``ABORT``
    (it gave up otherwise); ``ABORT`` where an uploaded program gave no usable path (``program``); ``UNKNOWN``
    where the run ended before its planning did (a testbed error, a cancel)."""
    if _planned(row) or (experiment is not None and _fleet_planned(experiment)):
        return PlannerStatus.EXACT_SOLUTION
    failure = row.get("failure")
    if failure == FailureKind.PLANNING:
        why = str(row.get("error") or "")
        why = why.split("planning failed:", 1)[1].strip() if "planning failed:" in why else why.strip()
        if why.startswith("start"):
            return PlannerStatus.INVALID_START
        if why.startswith("goal"):
            return PlannerStatus.INVALID_GOAL
        if re.search(r"cannot be reached|separate free regions|segment is blocked", why):
            return PlannerStatus.INFEASIBLE
        return PlannerStatus.ABORT
    if failure == FailureKind.PROGRAM:
        return PlannerStatus.ABORT
    return PlannerStatus.UNKNOWN


def _fleet_planned(experiment: Mapping[str, Any]) -> bool:
    paths = experiment.get("planned_paths") or []
    return bool(experiment.get("robots")) and bool(paths) and all(p is not None for p in paths)


def _run_path(row: Mapping[str, Any], experiment: Mapping[str, Any]) -> Optional[np.ndarray]:
    """The path this run's planner gave: the experiment's planned path where its length is the run's
    ``planned_length_m`` (a run that planned a path of its own that the study does not keep gets None)."""
    if not _planned(row) or experiment.get("planned_path") is None:
        return None
    path = np.asarray(experiment["planned_path"], dtype=float)
    if path.ndim != 2 or len(path) < 2:
        return None
    length = float(np.hypot(*np.diff(path[:, :2], axis=0).T).sum())
    if not math.isclose(length, row["planned_length_m"], rel_tol=_SAME_PATH, abs_tol=1e-4):
        return None
    return path


def _ompl_values(row: Mapping[str, Any], experiment: Mapping[str, Any], env: Any,
                 status: PlannerStatus) -> dict[str, Any]:
    out: dict[str, Any] = {"time": row.get("planning_time_s"), "status": int(status)}
    if status == PlannerStatus.UNKNOWN:
        return out  # solved: not known
    out["solved"] = status == PlannerStatus.EXACT_SOLUTION
    if status != PlannerStatus.EXACT_SOLUTION or experiment.get("robots"):
        return out  # a fleet's plan is several paths: OMPL's path properties are one path's
    out["approximate_solution"] = False
    out["solution_length"] = row.get("planned_length_m")
    collided = row.get("planned_collided")
    if isinstance(collided, bool):
        out["correct_solution"] = not collided
    path = _run_path(row, experiment)
    if path is not None:
        out["solution_smoothness"] = ompl_smoothness(path)
        out["solution_segments"] = len(path) - 1
        if env is not None:
            out["solution_clearance"] = ompl_clearance(env, path)
    return out


# ------------------------------------------------------------------ the database


def _sql_type(values: Iterable[Any]) -> Optional[str]:
    vals = [v for v in values if v is not None]
    if any(isinstance(v, str) for v in vals):
        return None
    if vals and all(isinstance(v, bool) for v in vals):
        return "BOOLEAN"
    if vals and all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
        return "INTEGER"
    return "REAL"


def _sql_value(v: Any) -> Any:
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, int) and not -(2 ** 63) <= v < 2 ** 63:
        return str(v)  # a 64-bit unsigned seed: SQLite's integers are signed
    return v


def _columns(c: sqlite3.Cursor, table: str) -> list[str]:
    return [r[1] for r in c.execute(f'PRAGMA table_info("{table}")')]


def _check_ompl(c: sqlite3.Cursor, path: Path) -> None:
    """Refuse a database that is not OMPL's benchmark schema (or whose status enum has other codes)."""
    try:
        tables = {r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError as exc:
        raise OmplExportError(f"{path} is not an SQLite database ({exc}); nothing was written") from None
    for table, required in _REQUIRED.items():
        if table not in tables:
            raise OmplExportError(f"{path} is not an OMPL benchmark database: it has no table {table!r} "
                                  f"(tables: {', '.join(sorted(tables)) or 'none'}); nothing was written")
        missing = [col for col in required if col not in _columns(c, table)]
        if missing:
            raise OmplExportError(f"{path} is not an OMPL benchmark database: table {table!r} lacks "
                                  f"{', '.join(missing)}; nothing was written")
    for value, description in c.execute("SELECT value, description FROM enums WHERE name = 'status'").fetchall():
        ours = STATUS_DESCRIPTIONS[value] if isinstance(value, int) and 0 <= value < len(STATUS_DESCRIPTIONS) else None
        if description != ours and not (value in _UNNAMED and description == _OMPL_UNKNOWN):
            hint = (" (an export of twb before it used OMPL's codes: write it anew with --replace)"
                    if description in {s.value for s in RunStatus} else "")
            raise OmplExportError(f"{path}: its status enum is not OMPL's PlannerStatus: value {value} is "
                                  f"{description!r}, OMPL's is {ours or 'none'!r}{hint}; nothing was written")


def check_ompl_database(db_path: str | Path) -> None:
    """Raise :class:`OmplExportError` unless ``db_path`` is an OMPL benchmark database this export can append to
    (reads it only)."""
    path = Path(db_path)
    if not path.is_file():
        raise OmplExportError(f"{path} is not a file")
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        _check_ompl(con.cursor(), path)
    except sqlite3.DatabaseError as exc:
        raise OmplExportError(f"{path}: {exc}") from None
    finally:
        con.close()


def _enum(c: sqlite3.Cursor, name: str, descriptions: tuple[str, ...], *, by_value: bool) -> tuple[dict[str, int], int]:
    """The codes of enum ``name``, adding the rows the database lacks; returns (description -> code, rows added).
    ``by_value``: the codes are fixed (OMPL's status: value i is ``descriptions[i]``); otherwise an existing
    enum's codes are kept and a description it lacks gets the next code."""
    have = dict(c.execute("SELECT value, description FROM enums WHERE name = ?", (name,)).fetchall())
    added = 0
    if by_value:
        for value, text in enumerate(descriptions):
            if value not in have:
                c.execute("INSERT INTO enums VALUES (?, ?, ?)", (name, value, text))
                added += 1
        return {text: value for value, text in enumerate(descriptions)}, added
    codes = {text: value for value, text in have.items()}
    for text in descriptions:
        if text not in codes:
            codes[text] = max(have, default=-1) + 1
            have[codes[text]] = text
            c.execute("INSERT INTO enums VALUES (?, ?, ?)", (name, codes[text], text))
            added += 1
    return codes, added


def _ompl_date(started: Any) -> Optional[str]:
    """A study's ISO start time as OMPL's logs write the date (``2026-11-27 16:02:14``, UTC here)."""
    if not started:
        return None
    try:
        return datetime.fromisoformat(str(started)).strftime("%Y-%m-%d %H:%M:%S")
    except ValueError:
        return str(started)


def _twb_version() -> str:
    try:
        from importlib.metadata import version

        return version("teleworkbench")
    except Exception:  # noqa: BLE001 -- a source tree without metadata
        return "0.0.0"


def _names(problems: list[tuple[str, str]], experiment: Optional[str | Mapping[str, str]],
           existing: list[str], notes: list[str]) -> dict[str, str]:
    """Each problem's experiment name: ``env-plan``, or as ``experiment`` says (one name for a one-problem
    study, or problem -> name), or, appending a one-problem study to a database of one experiment name, that
    name (so Planner Arena plots the two together)."""
    keys = [f"{env}-{plan}" for env, plan in problems]
    if isinstance(experiment, str):
        if len(keys) != 1:
            raise OmplExportError(f"one experiment name for {len(keys)} problems ({', '.join(keys)}): name each "
                                  "problem's (PROBLEM=NAME)")
        return {keys[0]: experiment}
    named = dict(experiment or {})
    unknown = [k for k in named if k not in keys]
    if unknown:
        raise OmplExportError(f"no problem {unknown[0]!r} in this study (its problems: {', '.join(keys)})")
    names = {k: named.get(k, k) for k in keys}
    if existing:
        distinct = list(dict.fromkeys(existing))
        if len(keys) == 1 and not named and keys[0] not in distinct and len(distinct) == 1:
            names[keys[0]] = distinct[0]
            notes.append(f"problem {keys[0]} written as the database's experiment {distinct[0]!r}")
        for k, name in names.items():
            if name not in distinct:
                notes.append(f"the database has no experiment {name!r} (it has {', '.join(map(repr, distinct))}): "
                             f"Planner Arena plots problem {k} apart from them; name it with --experiment {k}=NAME")
    return names


def _version(version: Optional[str], existing: list[str], notes: list[str]) -> str:
    if version:
        if existing and version not in existing:
            notes.append(f"version {version!r} is not the database's ({', '.join(map(repr, dict.fromkeys(existing)))}): "
                         "Planner Arena plots runs of one version at a time")
        return version
    distinct = list(dict.fromkeys(existing))
    if len(distinct) > 1:
        raise OmplExportError(f"the database holds experiments of {len(distinct)} versions "
                              f"({', '.join(map(repr, distinct))}): say which one to write with --version")
    return distinct[0] if distinct else f"Teleworkbench {_twb_version()}"


def _setup_study(setup: Any) -> Any:
    """The twb study an experiment's ``setup`` names (None for OMPL's setups, which are text)."""
    try:
        doc = json.loads(setup or "null")
    except (TypeError, ValueError):
        return None
    return doc.get("twb_study") if isinstance(doc, dict) else None


def _study_key(data: StudyData) -> dict[str, Any]:
    return {"name": data.spec.name, "server": data.meta.get("server"), "started_at": data.meta.get("started_at")}


def export_ompl(data: StudyData, db_path: str | Path, *, mode: Mode = "create",
                experiment: Optional[str | Mapping[str, str]] = None, version: Optional[str] = None) -> OmplExport:
    """Write ``data``'s runs as an OMPL benchmark database at ``db_path``.

    ``mode``: ``create`` (the default) refuses an existing file; ``append`` adds the study's experiments,
    planner configurations and runs to an existing OMPL benchmark database (created if missing), keeping
    every row it has, and refuses one that is not OMPL's schema; ``replace`` deletes an existing file first.
    ``experiment``: the experiment name of a one-problem study, or problem (``room-A``) -> name; appending a
    one-problem study to a database of one experiment name uses that name.  ``version``: the ``version``
    field (default: the appended-to database's, else ``Teleworkbench <version>``); Planner Arena plots together
    only runs of one experiment name and one version.  Raises :class:`OmplExportError`.
    """
    path = Path(db_path)
    if mode not in ("create", "append", "replace"):
        raise ValueError(f"mode must be create, append or replace, not {mode!r}")
    exists = path.exists()
    if exists and mode == "create":
        raise OmplExportError(f"{path} exists: --append adds this study's runs to it (its runs are kept), "
                              "--replace overwrites it")
    if exists and not path.is_file():
        raise OmplExportError(f"{path} is not a file")
    path.parent.mkdir(parents=True, exist_ok=True)
    # a replaced database is written beside it and moved over it at the end: a failed export keeps the old one
    target = path.with_name(f".{path.name}.twb-export") if exists and mode == "replace" else path
    if target != path:
        target.unlink(missing_ok=True)
        exists = False
    con = sqlite3.connect(target, isolation_level=None)  # one explicit transaction: all of it or nothing
    done: Optional[OmplExport] = None
    try:
        con.execute("PRAGMA FOREIGN_KEYS = ON")
        con.execute("BEGIN")
        done = _write(data, con, path, exists, experiment, version)
        con.execute("COMMIT")
    except sqlite3.DatabaseError as exc:
        raise OmplExportError(f"{path}: {exc}; nothing was written") from None
    finally:
        if con.in_transaction:
            con.execute("ROLLBACK")
        con.close()
        if done is None and not exists:
            target.unlink(missing_ok=True)  # the file this call created and could not fill
    if target != path:
        target.replace(path)
    return done


def _write(data: StudyData, con: sqlite3.Connection, path: Path, exists: bool,
           experiment: Optional[str | Mapping[str, str]], version: Optional[str]) -> OmplExport:
    c = con.cursor()
    notes: list[str] = []
    runs_before = 0
    existing_names: list[str] = []
    existing_versions: list[str] = []
    if exists:
        _check_ompl(c, path)
        runs_before = c.execute("SELECT count(*) FROM runs").fetchone()[0]
        rows = c.execute("SELECT name, version, setup FROM experiments").fetchall()
        existing_names = [r[0] for r in rows]
        existing_versions = [r[1] for r in rows]
        key = _study_key(data)
        if any(_setup_study(setup) == key for _, _, setup in rows):
            raise OmplExportError(f"{path} already holds the runs of study {key['name']!r} "
                                  f"(started {key['started_at']}); nothing was written")
    else:
        for statement in _SCHEMA.split(";"):
            if statement.strip():
                c.execute(statement)
    names = _names(data.problems, experiment, existing_names, notes)
    ver = _version(version, existing_versions, notes)

    counts = {"experiments": 0, "plannerConfigs": 0, "runs": 0, "enums": 0, "progress": 0}
    counts["enums"] += _enum(c, "status", STATUS_DESCRIPTIONS, by_value=True)[1]
    outcome_codes, added = _enum(c, OUTCOME, OUTCOME_ENUM, by_value=False)
    counts["enums"] += added

    exps = {e["experiment_id"]: e for e in data.experiments}
    envs = dict(data.environments)
    values: list[dict[str, Any]] = []
    for r in data.rows:
        e = exps.get(r.get("experiment_id")) or {}
        status = planner_status(r, e)
        v = _ompl_values(r, e, envs.get(str(r.get("environment"))), status)
        outcome = str(r.get("outcome") or "")
        if outcome and outcome not in outcome_codes:
            outcome_codes[outcome] = max(outcome_codes.values(), default=-1) + 1
            c.execute("INSERT INTO enums VALUES (?, ?, ?)", (OUTCOME, outcome_codes[outcome], outcome))
            counts["enums"] += 1
        v[OUTCOME] = outcome_codes.get(outcome)
        for k, x in r.items():
            if k not in _NOT_PROPERTIES and not isinstance(x, str):
                v[f"twb_{k}"] = x
        values.append(v)

    # the run properties: OMPL's, the outcome, then twb's metrics in runs.csv's order; added where missing
    types = dict(_OMPL_PROPERTIES)
    types[OUTCOME] = "ENUM"
    keys = list(dict.fromkeys(k for v in values for k in v))
    for k in keys:
        if k not in types:
            typ = _sql_type(v.get(k) for v in values)
            if typ is not None:
                types[k] = typ
    have = set(_columns(c, "runs"))
    for col, typ in types.items():
        if col not in have:
            c.execute(f'ALTER TABLE runs ADD "{col}" {typ}')

    exp_ids: dict[tuple[str, str], int] = {}
    key = _study_key(data)
    for env, plan in data.problems:
        mine = [e for e in data.experiments if (e["environment"], e["plan"]) == (env, plan)]
        rows = [r for r in data.rows if (r["environment"], r["plan"]) == (env, plan)]
        total = sum(r.get("execution_time_s") or 0.0 for r in rows) + sum(r.get("planning_time_s") or 0.0 for r in rows)
        problem = {"robots": mine[0]["robots"]} if mine[0].get("robots") else \
            {"start": mine[0]["start"], "goal": mine[0]["goal"]}
        setup = json.dumps({"environment": env, "plan": plan, **problem, "modes": data.spec.modes,
                            "repetitions": data.spec.repetitions, "field": data.spec.field,
                            "twb_study": key, "twb_version": _twb_version()})
        c.execute("INSERT INTO experiments (name, totaltime, timelimit, memorylimit, runcount, version, hostname, "
                  "cpuinfo, date, seed, setup) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                  (names[f"{env}-{plan}"], total, 0.0, 0.0, data.spec.repetitions, ver,
                   str(data.meta.get("server", "")),
                   "Teleworkbench emulator (sim: ideal robot; twb: emulated field robot)",
                   _ompl_date(data.meta.get("started_at")), str(data.spec.seed), setup))
        exp_ids[(env, plan)] = int(c.lastrowid or 0)
        counts["experiments"] += 1

    planner_ids: dict[tuple[str, str], int] = {}
    for e in data.experiments:
        for m in data.spec.modes:
            pk = (e["configuration"], m)
            if pk in planner_ids:
                continue
            name = f"{e['configuration']}_{m}"
            settings = json.dumps({"planner": e["planner"], "configuration": e["configuration"], "mode": m,
                                   "params": e.get("planner_params", {}), "controller": e.get("controller"),
                                   "twb_version": _twb_version()})
            found = c.execute("SELECT id FROM plannerConfigs WHERE name = ? AND settings = ?",
                              (name, settings)).fetchone()
            if found:
                planner_ids[pk] = found[0]
                continue
            c.execute("INSERT INTO plannerConfigs (name, settings) VALUES (?, ?)", (name, settings))
            planner_ids[pk] = int(c.lastrowid or 0)
            counts["plannerConfigs"] += 1

    cols = list(types)
    sql = (f"INSERT INTO runs (experimentid, plannerid, {', '.join(f'{chr(34)}{k}{chr(34)}' for k in cols)}) "
           f"VALUES ({', '.join('?' * (len(cols) + 2))})")
    curves = {e["experiment_id"]: e.get("repetition_progress") or {} for e in data.experiments}
    if any(curves.values()) and "best_cost" not in _columns(c, "progress"):
        c.execute('ALTER TABLE progress ADD "best_cost" REAL')
    for r, v in zip(data.rows, values):
        c.execute(sql, (exp_ids[(r["environment"], r["plan"])], planner_ids[(r["configuration"], r["mode"])],
                        *(_sql_value(v.get(k)) for k in cols)))
        counts["runs"] += 1
        curve = curves.get(r.get("experiment_id"), {}).get(str(r.get("repetition")))
        if curve:
            runid = int(c.lastrowid or 0)
            # one row per time (OMPL's primary key): the best length at each time the planner reported
            points = {float(t): float(cost) for t, cost in curve}
            c.executemany('INSERT INTO progress (runid, time, "best_cost") VALUES (?, ?, ?)',
                          [(runid, t, cost) for t, cost in sorted(points.items())])
            counts["progress"] += len(points)
    return OmplExport(path=path, version=ver, experiments=names, rows=counts, runs_before=runs_before, notes=notes)
