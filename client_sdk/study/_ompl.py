"""Export of a study to OMPL's benchmark database, the SQLite file Planner Arena plots.

The schema is the one ``ompl_benchmark_statistics.py`` creates (tables
``experiments``, ``plannerConfigs``, ``enums``, ``runs`` with one column per
run attribute, ``progress`` with one column per progress attribute).  The
mapping:

- one OMPL *experiment* per problem (environment and plan, e.g. ``room-A``);
- one *planner configuration* per configuration and mode (``fmm_sim``,
  ``fmm_twb``), its ``settings`` the planner parameters as JSON;
- one *run* per testbed run, with OMPL's usual attributes — ``time`` (planning
  time, s), ``solved`` (completed and goal reached), ``status`` (an ENUM),
  ``solution_length``/``solution_smoothness``/``solution_clearance`` (the
  planned path's) — and every metric of ``runs.csv`` under its own name
  (performed path, ratios, ``st_*`` direct comparison, ``planned_*``);
- *progress*: the robot's way to the goal, once per experiment second from
  ``EV,START`` (``time``), as ``distance_to_goal`` and ``path_length`` so far
  (not for a fleet study: its runs have a goal per robot; a fleet problem's
  ``setup`` holds its ``robots``).
"""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np

from contract.vocabulary import TERMINAL, RunStatus

from ._data import ID_COLUMNS, StudyData

__all__ = ["STATUS_ENUM", "export_ompl"]

STATUS_ENUM = tuple(s.value for s in RunStatus if s in TERMINAL)  #: the status enum's codes, in order
VERSION = "Teleworkbench 0.1.0"

_SCHEMA = """
CREATE TABLE experiments
    (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512),
    totaltime REAL, timelimit REAL, memorylimit REAL, runcount INTEGER,
    version VARCHAR(128), hostname VARCHAR(1024), cpuinfo TEXT,
    date DATETIME, seed INTEGER, setup TEXT);
CREATE TABLE plannerConfigs
    (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512) NOT NULL, settings TEXT);
CREATE TABLE enums
    (name VARCHAR(512), value INTEGER, description TEXT, PRIMARY KEY (name, value));
CREATE TABLE runs
    (id INTEGER PRIMARY KEY AUTOINCREMENT, experimentid INTEGER, plannerid INTEGER,
    FOREIGN KEY (experimentid) REFERENCES experiments(id) ON DELETE CASCADE,
    FOREIGN KEY (plannerid) REFERENCES plannerConfigs(id) ON DELETE CASCADE);
CREATE TABLE progress
    (runid INTEGER, time REAL, distance_to_goal REAL, path_length REAL, PRIMARY KEY (runid, time),
    FOREIGN KEY (runid) REFERENCES runs(id) ON DELETE CASCADE);
"""

#: OMPL's conventional run attributes, from the planned path's metrics
_OMPL_ALIASES = {"time": "planning_time_s", "solution_length": "planned_length_m",
                 "solution_smoothness": "planned_smoothness_rad", "solution_clearance": "planned_clearance_min_m"}
_SKIP = set(ID_COLUMNS) - {"repetition", "seed", "planner_seed", "subfield"}


def _sql_type(values: list[Any]) -> str:
    vals = [v for v in values if v is not None]
    if vals and all(isinstance(v, bool) for v in vals):
        return "BOOLEAN"
    if vals and all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
        return "INTEGER"
    return "REAL"


def _num(v: Any) -> Any:
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _progress(poses: np.ndarray, t_start: Any, goal: list[float]) -> list[tuple[float, float, float]]:
    if len(poses) < 2:
        return []
    t0 = float(t_start) if isinstance(t_start, (int, float)) else float(poses[0, 0])
    p = poses[poses[:, 0] >= t0 - 1e-9]
    if len(p) < 2:
        return []
    steps = np.r_[0.0, np.cumsum(np.hypot(np.diff(p[:, 1]), np.diff(p[:, 2])))]
    t = p[:, 0] - t0
    out, next_t = [], 0.0
    for i in range(len(p)):
        if t[i] >= next_t - 1e-9 or i == len(p) - 1:
            d = math.hypot(goal[0] - p[i, 1], goal[1] - p[i, 2])
            out.append((round(float(t[i]), 3), d, float(steps[i])))
            next_t = math.floor(t[i]) + 1.0
    return list({row[0]: row for row in out}.values())


def export_ompl(data: StudyData, db_path: str | Path, *, progress: bool = True) -> dict[str, int]:
    """Write ``data`` as an OMPL benchmark database at ``db_path`` (replaced if it exists).

    Returns the number of rows written per table.  ``progress=False`` skips
    the per-second progress rows (they need the study's poses).
    """
    path = Path(db_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists():
        path.unlink()
    rows = data.rows
    attrs: dict[str, str] = {}
    for alias, key in _OMPL_ALIASES.items():
        attrs[alias] = "REAL"
    attrs["solved"] = "BOOLEAN"
    attrs["status"] = "ENUM"
    for key in dict.fromkeys(k for r in rows for k in r):
        if key in _SKIP or key in attrs:
            continue
        values = [r.get(key) for r in rows]
        if any(isinstance(v, str) for v in values):
            continue
        attrs["twb_run_id" if key == "run_id" else key] = _sql_type(values)
    attrs["twb_run_id"] = "INTEGER"
    counts = {"experiments": 0, "plannerConfigs": 0, "runs": 0, "progress": 0, "enums": 0}
    con = sqlite3.connect(path)
    try:
        c = con.cursor()
        c.execute("PRAGMA FOREIGN_KEYS = ON")
        c.executescript(_SCHEMA)
        for col, typ in attrs.items():
            c.execute(f'ALTER TABLE runs ADD "{col}" {typ}')
        c.executemany("INSERT INTO enums VALUES (?, ?, ?)", [("status", i, s) for i, s in enumerate(STATUS_ENUM)])
        counts["enums"] = len(STATUS_ENUM)
        exp_ids: dict[tuple[str, str], int] = {}
        planner_ids: dict[tuple[str, str], int] = {}
        host = str(data.meta.get("server", ""))
        date = str(data.meta.get("started_at", ""))
        for env, plan in data.problems:
            exps = [e for e in data.experiments if (e["environment"], e["plan"]) == (env, plan)]
            mine = [r for r in rows if (r["environment"], r["plan"]) == (env, plan)]
            total = sum(r.get("execution_time_s") or 0.0 for r in mine) + sum(e.get("planning_time_s") or 0.0 for e in exps)
            problem = {"robots": exps[0]["robots"]} if exps[0].get("robots") else \
                {"start": exps[0]["start"], "goal": exps[0]["goal"]}
            setup = json.dumps({"environment": env, "plan": plan, **problem,
                                "modes": data.spec.modes, "repetitions": data.spec.repetitions,
                                "field": data.spec.field, "study": data.spec.name})
            c.execute("INSERT INTO experiments VALUES (NULL, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                      (f"{env}-{plan}", total, 0.0, 0.0, data.spec.repetitions, VERSION, host,
                       "emulated Teleworkbench (sim: ideal robot, twb: emulated field robot)", date, data.spec.seed,
                       setup))
            exp_ids[(env, plan)] = c.lastrowid
            counts["experiments"] += 1
        for e in data.experiments:
            for mode in data.spec.modes:
                key = (e["configuration"], mode)
                if key not in planner_ids:
                    settings = json.dumps({"planner": e["planner"], "configuration": e["configuration"], "mode": mode,
                                           "params": e["planner_params"]})
                    c.execute("INSERT INTO plannerConfigs VALUES (NULL, ?, ?)",
                              (f"{e['configuration']}_{mode}", settings))
                    planner_ids[key] = c.lastrowid
                    counts["plannerConfigs"] += 1
        cols = list(attrs)
        sql = (f"INSERT INTO runs (experimentid, plannerid, {', '.join(f'{chr(34)}{k}{chr(34)}' for k in cols)}) "
               f"VALUES ({', '.join('?' * (len(cols) + 2))})")
        goal_of = {e["experiment_id"]: e["goal"] for e in data.experiments}
        for r in rows:
            vals = []
            for col in cols:
                if col in _OMPL_ALIASES:
                    v = r.get(_OMPL_ALIASES[col])
                elif col == "solved":
                    v = r.get("status") == "completed" and bool(r.get("goal_reached"))
                elif col == "status":
                    v = STATUS_ENUM.index(r["status"]) if r.get("status") in STATUS_ENUM else None
                elif col == "twb_run_id":
                    v = r.get("run_id")
                else:
                    v = r.get(col)
                vals.append(_num(v))
            c.execute(sql, (exp_ids[(r["environment"], r["plan"])], planner_ids[(r["configuration"], r["mode"])], *vals))
            run_rowid = c.lastrowid
            counts["runs"] += 1
            if progress and r.get("status") == "completed" and not data.spec.fleet:  # a fleet has no one goal
                try:
                    poses = data.poses(r["run_id"])
                except KeyError:
                    continue
                prog = _progress(poses, r.get("t_start"), goal_of[r["experiment_id"]])
                c.executemany("INSERT INTO progress (runid, time, distance_to_goal, path_length) VALUES (?, ?, ?, ?)",
                              [(run_rowid, *p) for p in prog])
                counts["progress"] += len(prog)
        con.commit()
    finally:
        con.close()
    return counts
