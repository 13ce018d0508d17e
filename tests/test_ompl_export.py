"""The OMPL benchmark database export (`twb export-ompl`, docs/study.md "OMPL / Planner Arena") without a testbed.

A study made in memory (real planned paths in the room, a run per row with its own planning time and planned
length, every way a run ends), exported and read back with OMPL's schema and semantics; appended to a database
made as OMPL's ompl_benchmark_statistics.py makes one (every OMPL row kept); refusals.  Where the `ompl` and
`plannerarena` packages are installed (the `ompl` extra), also against OMPL's real Benchmark class, its
log-to-database script and PathGeometric, and Planner Arena's own loading and plotting code.
"""

from __future__ import annotations

import json
import math
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from client_sdk.study import OmplExportError, PlannerStatus, StudyData, StudySpec, export_ompl
from client_sdk.study._ompl import OUTCOME_ENUM, STATUS_DESCRIPTIONS, ompl_clearance, ompl_smoothness
from contract.vocabulary import TERMINAL, RunStatus
from planners import load_environment, plan_path
from sdk_helpers import invoke

ROOM = json.loads((Path(__file__).resolve().parents[1] / "planners" / "data" / "room.json").read_text())
START, GOAL = [0.3, 0.3, 0.0], [1.5, 1.5, 1.5708]
REPS = 5
#: OMPL's ompl::base::PlannerStatus::StatusType, in order (src/ompl/base/PlannerStatus.h)
OMPL_STATUS_NAMES = ("UNKNOWN", "INVALID_START", "INVALID_GOAL", "UNRECOGNIZED_GOAL_TYPE", "TIMEOUT",
                     "APPROXIMATE_SOLUTION", "EXACT_SOLUTION", "CRASH", "ABORT", "INFEASIBLE")
#: the status enum OMPL 2.0.1's benchmark log declares (PlannerStatus::asString() has no case for ABORT, INFEASIBLE)
OMPL_201_STATUS = ("Unknown status", "Invalid start", "Invalid goal", "Unrecognized goal type", "Timeout",
                   "Approximate solution", "Exact solution", "Crash", "Unknown status", "Unknown status")

# every way a run ends: (status, failure, error, planned); planned False: the run has no planned path
ENDINGS = {
    "fmm": [("completed", None, "", True)] * 3 + [("failed", "collision", "collision at (0.9, 0.5)", True),
                                                  ("error", None, "robot unreachable", False)],
    "prm": [("completed", None, "", True)] * 2 + [
        ("failed", "planning", "planning failed: the goal (1.5, 1.5) cannot be reached from the start (0.3, 0.3): "
                               "they are in separate free regions for a robot of radius 0.045 m", False),
        ("failed", "planning", "planning failed: goal (1.5, 1.5) is inside an obstacle or closer than the robot "
                               "radius 0.045 m to one", False),
        ("cancelled", None, "cancelled by its owner", False)],
}
EXPECTED = {  # (status code, solved) per ending above
    "fmm": [(6, 1)] * 3 + [(6, 1), (0, None)],
    "prm": [(6, 1)] * 2 + [(9, 0), (2, 0), (0, None)],
}


def make_study(seed: int = 7, name: str = "synthetic") -> StudyData:
    """A one-problem study of fmm and prm in the room, sim and twb, REPS runs each, made in memory: every run has
    its own planning time and planned length (the first run of each mode plans the experiment's stored path)."""
    spec = StudySpec.from_json({"name": name, "environments": ["room"], "plans": ["A"], "planners": ["fmm", "prm"],
                                "repetitions": REPS, "modes": ["sim", "twb"], "seed": seed})
    env = load_environment(ROOM)
    experiments, rows, run_id = [], [], 0
    for exp_id, planner in enumerate(("fmm", "prm"), 1):
        plan = plan_path(env, START, GOAL, planner, seed=seed)
        path = np.round(plan.path, 6)
        length = float(np.hypot(*np.diff(path[:, :2], axis=0).T).sum())
        runs = []
        for mode in ("sim", "twb"):
            for rep, (status, failure, error, planned) in enumerate(ENDINGS[planner], 1):
                run_id += 1
                runs.append(run_id)
                row = {"study": name, "experiment_id": exp_id, "run_id": run_id, "environment": "room", "plan": "A",
                       "planner": planner, "controller": "schema", "configuration": planner, "mode": mode,
                       "repetition": rep, "seed": 2 ** 63 + run_id,  # a 64-bit unsigned seed
                       "status": status, "failure": failure, "error": error, "t_start": 1.0, "t_end": 12.0,
                       "length_m": length * (1 + 0.01 * rep), "smoothness_rad": 0.1 * rep, "goal_reached": status == "completed",
                       "collided": failure == "collision", "execution_time_s": 10.0 + rep}
                if planned:  # a path of its own (its length differs) but for the first run, which planned the stored one
                    row.update(planning_time_s=0.01 + 0.003 * rep + (0.001 if mode == "twb" else 0.0),
                               planned_length_m=length if rep == 1 else length * (1 + 0.002 * rep),
                               planned_smoothness_rad=0.2, planned_clearance_min_m=0.05, planned_collided=False)
                rows.append(row)
        experiments.append({"experiment_id": exp_id, "environment": "room", "plan": "A", "planner": planner,
                            "controller": "schema", "configuration": planner, "planner_params": {}, "start": START,
                            "goal": GOAL, "repetitions": REPS, "modes": ["sim", "twb"], "status": "completed",
                            "planned_path": path.tolist(), "planning_time_s": plan.planning_time_s, "runs": runs})
    return StudyData(spec=spec, environments={"room": ROOM}, experiments=experiments, rows=rows, direct=[],
                     meta={"server": "http://127.0.0.1:8000", "started_at": f"2026-11-27T10:00:0{seed % 10}+00:00"})


@pytest.fixture(scope="module")
def study() -> StudyData:
    return make_study()


def query(db: Path, sql: str, *args) -> list[tuple]:  # type: ignore[no-untyped-def]
    con = sqlite3.connect(db)
    try:
        return con.execute(sql, args).fetchall()
    finally:
        con.close()


def table_rows(db: Path) -> dict[str, list[tuple]]:
    """Every row of OMPL's five tables (runs and progress: every column they have)."""
    con = sqlite3.connect(db)
    try:
        return {t: con.execute(f"SELECT * FROM {t} ORDER BY 1, 2").fetchall()
                for t in ("experiments", "plannerConfigs", "enums", "runs", "progress")}
    finally:
        con.close()


# ------------------------------------------------------------------ one row per run, OMPL's semantics


def test_one_row_per_run_with_its_own_planning_time_and_planned_length(study, tmp_path):
    done = export_ompl(study, tmp_path / "s.db")
    assert done["runs"] == len(study.rows) == 20 and done["progress"] == 0
    runs = query(tmp_path / "s.db", "SELECT p.name, r.twb_run_id, r.time, r.solution_length FROM runs r "
                                    "JOIN plannerConfigs p ON p.id = r.plannerid")
    by_planner: dict[str, list[tuple]] = {}
    for name, *rest in runs:
        by_planner.setdefault(name, []).append(tuple(rest))
    assert sorted(by_planner) == ["fmm_sim", "fmm_twb", "prm_sim", "prm_twb"]
    rows = {r["run_id"]: r for r in study.rows}
    for name, mine in by_planner.items():
        assert len(mine) == REPS  # n rows per planner and problem, not one
        planned = [(t, length) for _, t, length in mine if t is not None]
        assert len({t for t, _ in planned}) == len(planned) >= 2  # each its own time: a box, not a line
        assert len({length for _, length in planned}) == len(planned)
        for run_id, t, length in mine:
            assert t == rows[run_id].get("planning_time_s") and length == rows[run_id].get("planned_length_m")
    assert query(tmp_path / "s.db", "SELECT count(*) FROM progress") == [(0,)]  # twb's planners are not anytime


def test_an_anytime_planners_runs_carry_their_repetitions_progress(tmp_path):
    """Progress rows (OMPL's ``time``, ``best_cost``) for each run of a planner that reported its best length over
    its planning time: its repetition's curve (``study.json``'s ``repetition_progress``), both modes."""
    data = make_study(name="anytime")
    curves = {"1": [[0.01, 2.4], [0.05, 2.2], [0.2, 2.1]], "2": [[0.02, 2.5], [0.3, 2.05]]}
    data.experiments[1]["repetition_progress"] = curves  # prm's, as if it were an anytime planner
    done = export_ompl(data, tmp_path / "p.db")
    got = query(tmp_path / "p.db", "SELECT r.twb_run_id, p.time, p.best_cost FROM progress p "
                                   "JOIN runs r ON r.id = p.runid ORDER BY 1, 2")
    want = sorted((r["run_id"], t, c) for r in data.rows if r["experiment_id"] == 2
                  for t, c in curves.get(str(r["repetition"]), []))
    assert got == want and done["progress"] == len(want) == 10  # 2 modes x (3 + 2) points


def test_status_is_the_planners_result_in_omplss_codes_and_the_outcome_its_own_enum(study, tmp_path):
    assert [s.name for s in PlannerStatus] == list(OMPL_STATUS_NAMES)
    assert [s.value for s in PlannerStatus] == list(range(10))
    export_ompl(study, tmp_path / "s.db")
    db = tmp_path / "s.db"
    assert query(db, "SELECT value, description FROM enums WHERE name = 'status' ORDER BY value") == \
        list(enumerate(STATUS_DESCRIPTIONS))
    assert STATUS_DESCRIPTIONS[:8] == OMPL_201_STATUS[:8]
    outcomes = dict(query(db, "SELECT description, value FROM enums WHERE name = 'twb_outcome'"))
    assert list(outcomes) == list(OUTCOME_ENUM)
    got = query(db, "SELECT r.twb_run_id, r.status, r.solved, r.twb_outcome FROM runs r ORDER BY r.twb_run_id")
    rows = {r["run_id"]: r for r in study.rows}
    for run_id, status, solved, outcome in got:
        row = rows[run_id]
        assert (status, solved) == EXPECTED[row["planner"]][row["repetition"] - 1], row
        assert outcome == outcomes[row["outcome"]]
    # the robot failing to follow a path the planner found is not the planner's failure
    collided = [g for g in got if rows[g[0]]["failure"] == "collision"]
    assert collided and all(status == PlannerStatus.EXACT_SOLUTION and solved == 1 for _, status, solved, _ in collided)


def test_ompl_path_quantities_of_the_planned_path_and_twbs_own_under_twb_names(study, tmp_path):
    export_ompl(study, tmp_path / "s.db")
    cols = {r[1]: r[2] for r in query(tmp_path / "s.db", "PRAGMA table_info(runs)")}
    for col, typ in {"time": "REAL", "solved": "BOOLEAN", "status": "ENUM", "solution_length": "REAL",
                     "solution_smoothness": "REAL", "solution_clearance": "REAL", "solution_segments": "INTEGER",
                     "twb_outcome": "ENUM", "twb_length_m": "REAL", "twb_smoothness_rad": "REAL",
                     "twb_execution_time_s": "REAL", "twb_goal_reached": "BOOLEAN", "twb_run_id": "INTEGER",
                     "twb_planned_smoothness_rad": "REAL"}.items():
        assert cols.get(col) == typ, col
    assert not {"length_m", "smoothness_rad", "planned_length_m", "goal_reached", "run_id"} & set(cols)
    env = load_environment(ROOM)
    for e in study.experiments:
        path = np.asarray(e["planned_path"])
        first = [r["run_id"] for r in study.rows if r["experiment_id"] == e["experiment_id"] and r["repetition"] == 1]
        got = query(tmp_path / "s.db", "SELECT solution_smoothness, solution_clearance, solution_segments, "
                    f"correct_solution FROM runs WHERE twb_run_id IN ({','.join(map(str, first))})")
        assert got == [(ompl_smoothness(path), ompl_clearance(env, path), len(path) - 1, 1)] * 2
        assert got[0][0] > 0 and 0 < got[0][1] < 0.9
    # a run that planned a path of its own (another length) that the study does not keep: not guessed
    other = [r["run_id"] for r in study.rows if r.get("planned_length_m") and r["repetition"] > 1]
    assert query(tmp_path / "s.db", "SELECT DISTINCT solution_smoothness, solution_clearance FROM runs "
                 f"WHERE twb_run_id IN ({','.join(map(str, other))})") == [(None, None)]


def test_ompl_smoothness_by_hand():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)  # two right turns, segments of 1
    assert ompl_smoothness(square) == pytest.approx(2 * (2 * (math.pi / 2) / 2) ** 2)
    assert ompl_smoothness([[0, 0], [1, 0], [2, 0], [2, 0], [3, 0]]) == 0.0  # straight, a repeated point
    assert ompl_smoothness([[0, 0], [1, 0]]) == 0.0


# ------------------------------------------------------------------ appending to OMPL's database


def ompl_reference_db(path: Path) -> None:
    """A database as OMPL 2.0.1's ompl_benchmark_statistics.py writes one from a benchmark log: its tables, the
    log's status enum, a run's properties as columns (spaces become _), an anytime planner's progress, its views."""
    con = sqlite3.connect(path)
    c = con.cursor()
    c.executescript("""
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
        FOREIGN KEY (runid) REFERENCES runs(id) ON DELETE CASCADE)""")
    c.execute("INSERT INTO experiments (name, totaltime, timelimit, memorylimit, runcount, version, hostname, cpuinfo, "
              "date, seed, setup) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
              ("room-A", 4.2, 1.0, 4096.0, 4, "OMPL 2.0.1", "ompl-host", "Architecture: x86_64\n",
               "2026-11-20 10:00:00", "1795795334559017", "Properties of the state space 'RealVectorSpace0'\n"))
    for value, description in enumerate(OMPL_201_STATUS):
        c.execute("INSERT INTO enums VALUES (?,?,?)", ("status", value, description))
    for name in ("geometric_RRTConnect", "geometric_RRTstar"):
        c.execute("INSERT INTO plannerConfigs VALUES (?,?,?)", (None, name, "range = 0\n;rewire_factor = 1.1\n;"))
    for prop, typ in (("approximate_solution", "BOOLEAN"), ("correct_solution", "BOOLEAN"), ("graph_states", "INTEGER"),
                      ("memory", "REAL"), ("simplification_time", "REAL"), ("solution_clearance", "REAL"),
                      ("solution_length", "REAL"), ("solution_segments", "INTEGER"), ("solution_smoothness", "REAL"),
                      ("solved", "BOOLEAN"), ("status", "ENUM"), ("time", "REAL"), ("best_cost", "REAL")):
        c.execute(f"ALTER TABLE runs ADD {prop} {typ}")
    runs = [  # plannerid, status, solved, time, length; RRTstar's runs report progress
        (1, 6, 1, 0.0031, 2.31), (1, 6, 1, 0.0042, 2.48), (1, 4, 0, 1.0, None), (1, 9, 0, 0.2, None),
        (2, 6, 1, 1.0, 1.95), (2, 6, 1, 1.0, 1.97), (2, 5, 0, 1.0, 2.6), (2, 6, 1, 1.0, 2.01)]
    for i, (planner, status, solved, t, length) in enumerate(runs):
        c.execute("INSERT INTO runs (experimentid, plannerid, approximate_solution, correct_solution, graph_states, "
                  "memory, simplification_time, solution_clearance, solution_length, solution_segments, "
                  "solution_smoothness, solved, status, time, best_cost) VALUES (1,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                  (planner, int(status == 5), 1 if length else None, 40 + i, 24.8, 0.0004, 0.0 if length else None,
                   length, 5 if length else None, 1.5 if length else None, solved, status, t,
                   length if planner == 2 else None))
    c.execute("ALTER TABLE progress ADD best_cost REAL")
    c.execute("ALTER TABLE progress ADD iterations INTEGER")
    rng = np.random.default_rng(3)
    for runid in range(5, 9):
        for k in range(1, 101):  # every 0.01 s, as a Request's timeBetweenUpdates would sample
            c.execute("INSERT INTO progress VALUES (?,?,?,?)",
                      (runid, round(0.01 * k + rng.uniform(0, 0.001), 5), 2.0 + 1.0 / k, 10 * k))
    c.execute("CREATE VIEW IF NOT EXISTS bestPlannerConfigs AS SELECT plannerid, AVG(solved) AS avg_solved, "
              "AVG(time + simplification_time) AS avg_total_time FROM runs GROUP BY plannerid")
    con.commit()
    con.close()


def assert_kept(before: dict[str, list[tuple]], after: dict[str, list[tuple]]) -> None:
    """Every row ``before`` had is in ``after`` unchanged (its columns first; added columns empty)."""
    for table, rows in before.items():
        width = len(rows[0]) if rows else 0
        old = {r[:2] if table in ("enums", "progress") else r[0]: r for r in rows}
        new = {r[:2] if table in ("enums", "progress") else r[0]: r for r in after[table]}
        for key, row in old.items():
            assert new[key][:width] == row, (table, key)
            if table == "runs":
                assert all(v is None for v in new[key][width:]), (table, key)


def test_appending_to_a_database_ompls_tools_wrote_keeps_every_ompl_run(study, tmp_path):
    db = tmp_path / "ompl.db"
    ompl_reference_db(db)
    before = table_rows(db)
    done = export_ompl(study, db, mode="append")
    after = table_rows(db)
    assert_kept(before, after)
    assert done.runs_before == 8 and done["runs"] == 20 and len(after["runs"]) == 28
    assert len(after["progress"]) == len(before["progress"]) == 400
    # under the OMPL experiment's name and version: Planner Arena plots them together
    assert done.version == "OMPL 2.0.1" and done.experiments == {"room-A": "room-A"}
    both = query(db, "SELECT DISTINCT p.name FROM runs r JOIN plannerConfigs p ON p.id = r.plannerid "
                     "JOIN experiments e ON e.id = r.experimentid WHERE e.name = 'room-A' AND e.version = 'OMPL 2.0.1'")
    assert {n for (n,) in both} == {"geometric_RRTConnect", "geometric_RRTstar", "fmm_sim", "fmm_twb", "prm_sim",
                                    "prm_twb"}
    # OMPL's status enum as it was (its 'Unknown status' for ABORT and INFEASIBLE kept); twb's outcome beside it
    assert query(db, "SELECT description FROM enums WHERE name = 'status' ORDER BY value") == \
        [(d,) for d in OMPL_201_STATUS]
    # the status chart counts every run: OMPL's codes throughout
    counts = dict(query(db, "SELECT e.description, count(*) FROM runs r JOIN enums e ON e.name = 'status' "
                            "AND e.value = r.status GROUP BY e.description"))
    assert sum(counts.values()) == 28
    assert query(db, "SELECT count(*) FROM bestPlannerConfigs") == [(6,)]  # OMPL's view still reads the table
    # appending the same study twice would count its runs twice
    with pytest.raises(OmplExportError, match="already holds the runs of study 'synthetic'"):
        export_ompl(study, db, mode="append")
    assert table_rows(db) == after
    # another study of the same problem joins them
    assert export_ompl(make_study(seed=8, name="again"), db, mode="append").runs_before == 28


def test_an_experiment_name_and_version_of_ones_choice(study, tmp_path):
    db = tmp_path / "ompl.db"
    ompl_reference_db(db)
    sqlite3.connect(db).execute("UPDATE experiments SET name = 'Maze'").connection.commit()
    done = export_ompl(study, db, mode="append")  # one problem into a database of one experiment: its name
    assert done.experiments == {"room-A": "Maze"} and "written as the database's experiment 'Maze'" in done.notes[0]
    fresh = export_ompl(study, tmp_path / "new.db", experiment={"room-A": "Maze"}, version="OMPL 2.0.1")
    assert fresh.experiments == {"room-A": "Maze"} and fresh.notes == []
    assert query(tmp_path / "new.db", "SELECT name, version FROM experiments") == [("Maze", "OMPL 2.0.1")]
    assert export_ompl(study, tmp_path / "t.db").version.startswith("Teleworkbench ")
    with pytest.raises(OmplExportError, match="no problem 'blocks-B'"):
        export_ompl(study, tmp_path / "x.db", experiment={"blocks-B": "X"})
    assert not (tmp_path / "x.db").exists()  # a refused export leaves no file behind
    con = sqlite3.connect(db)
    con.execute("UPDATE experiments SET version = 'OMPL 1.6.0' WHERE id = 1")
    con.commit()
    con.close()
    with pytest.raises(OmplExportError, match="2 versions .*--version"):
        export_ompl(make_study(seed=9, name="third"), db, mode="append")


def test_an_existing_database_is_never_deleted_unless_asked(study, tmp_path):
    db = tmp_path / "ompl.db"
    ompl_reference_db(db)
    before = table_rows(db)
    with pytest.raises(OmplExportError, match="exists: --append .* --replace"):
        export_ompl(study, db)
    assert table_rows(db) == before
    with pytest.raises(OmplExportError, match="no problem 'blocks-B'"):  # a replacement that fails: the old kept
        export_ompl(study, db, mode="replace", experiment={"blocks-B": "X"})
    assert table_rows(db) == before and sorted(f.name for f in tmp_path.iterdir()) == ["ompl.db"]
    export_ompl(study, db, mode="replace")
    assert query(db, "SELECT count(*) FROM runs") == [(20,)]
    assert sorted(f.name for f in tmp_path.iterdir()) == ["ompl.db"]


@pytest.mark.parametrize("make, message", [
    (lambda c: c.execute("CREATE TABLE runs (id INTEGER, x REAL)"), "not an OMPL benchmark database: it has no table"),
    (lambda c: c.executescript(
        "CREATE TABLE experiments (id INTEGER PRIMARY KEY, name TEXT); CREATE TABLE plannerConfigs (id, name, settings);"
        "CREATE TABLE enums (name, value, description); CREATE TABLE runs (id, experimentid, plannerid);"
        "CREATE TABLE progress (runid, time)"), "table 'experiments' lacks totaltime"),
])
def test_a_database_that_is_not_omplss_is_refused(study, tmp_path, make, message):
    db = tmp_path / "other.db"
    con = sqlite3.connect(db)
    make(con)
    con.commit()
    con.close()
    size = db.stat().st_size
    with pytest.raises(OmplExportError, match=message):
        export_ompl(study, db, mode="append")
    assert db.stat().st_size == size
    (tmp_path / "text.db").write_text("not a database\n")
    with pytest.raises(OmplExportError, match="not an SQLite database"):
        export_ompl(study, tmp_path / "text.db", mode="append")
    assert (tmp_path / "text.db").read_text() == "not a database\n"


def test_a_database_of_twbs_earlier_export_is_refused_with_the_way_out(study, tmp_path):
    db = tmp_path / "old.db"
    ompl_reference_db(db)
    con = sqlite3.connect(db)
    con.execute("DELETE FROM enums")
    old_codes = [s.value for s in RunStatus if s in TERMINAL]  # the status enum twb's export used to write
    con.executemany("INSERT INTO enums VALUES ('status', ?, ?)", enumerate(old_codes))
    con.commit()
    con.close()
    with pytest.raises(OmplExportError, match=r"value 0 is 'completed', OMPL's is 'Unknown status' .*--replace"):
        export_ompl(study, db, mode="append")


def test_export_ompl_command_appends_replaces_and_refuses(capsys, monkeypatch, study, tmp_path):
    d = tmp_path / "study"
    study.save(d)
    db = tmp_path / "ompl.db"
    ompl_reference_db(db)
    r = invoke(capsys, monkeypatch, "export-ompl", str(d), "--out", str(db))
    assert r.returncode == 2 and "exists: --append adds the runs to it" in r.stderr and r.stderr.count("\n") == 1
    r = invoke(capsys, monkeypatch, "export-ompl", str(d), "--out", str(db), "--append")
    assert r.returncode == 0, r.stderr
    assert "1 experiments (room-A), 4 planner configurations, 20 runs added (kept its 8 runs); version 'OMPL 2.0.1'" \
        in r.stdout
    r = invoke(capsys, monkeypatch, "export-ompl", str(d), "--out", str(tmp_path / "n.db"), "--experiment",
               "room-A=Maze", "--version", "OMPL 2.0.1")
    assert r.returncode == 0 and "(Maze)" in r.stdout and "version 'OMPL 2.0.1'" in r.stdout
    r = invoke(capsys, monkeypatch, "export-ompl", str(d), "--out", str(tmp_path / "n.db"), "--replace")
    assert r.returncode == 0 and "20 runs added;" in r.stdout
    r = invoke(capsys, monkeypatch, "export-ompl", str(d), "--append", "--replace")
    assert r.returncode == 2 and "either --append or --replace" in r.stderr
    r = invoke(capsys, monkeypatch, "export-ompl", str(d), "--out", str(tmp_path / "m.db"), "--experiment", "a",
               "--experiment", "b")
    assert r.returncode == 2 and "PROBLEM=NAME" in r.stderr


# ------------------------------------------------------------------ OMPL's own tools and Planner Arena


@pytest.fixture(scope="module")
def ompl_db(tmp_path_factory) -> Path:
    """A database OMPL's real tools made, as docs/study.md does: examples/ompl_room_benchmark.py runs OMPL's
    Benchmark class (RRTConnect, and RRT* reporting progress) on the room's plan A, ompl_benchmark_statistics
    reads its log."""
    pytest.importorskip("ompl", reason="the ompl package is not installed (pip install -e '.[ompl]')")
    d = tmp_path_factory.mktemp("ompl")
    example = Path(__file__).resolve().parents[1] / "examples" / "ompl_room_benchmark.py"
    r = subprocess.run([sys.executable, str(example), "--runs", "3", "--time", "0.5"], cwd=d, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0 and "wrote room-A.log" in r.stdout, r.stderr[-2000:]
    r = subprocess.run([sys.executable, "-m", "ompl.ompl_benchmark_statistics", "-d", str(d / "ompl.db"),
                        str(d / "room-A.log")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return d / "ompl.db"


def test_omplss_real_status_codes():
    ob = pytest.importorskip("ompl.base", reason="the ompl package is not installed (pip install -e '.[ompl]')")
    members = {name: getattr(ob.PlannerStatus, name).value for name in OMPL_STATUS_NAMES}
    assert members == {s.name: s.value for s in PlannerStatus}


def test_smoothness_and_clearance_equal_omplss_path_geometric(study):
    ob = pytest.importorskip("ompl.base", reason="the ompl package is not installed (pip install -e '.[ompl]')")
    og = pytest.importorskip("ompl.geometric")
    from planners.geometry import distance_to_obstacles

    env = load_environment(ROOM)

    class Clearance(ob.StateValidityChecker):  # twb's state clearance: the centre's distance to the obstacles
        def isValid(self, state):  # type: ignore[no-untyped-def]
            return True

        def clearance(self, state):  # type: ignore[no-untyped-def]
            return float(distance_to_obstacles(env, np.array([[state[0], state[1]]]))[0])

    space = ob.RealVectorStateSpace(2)
    bounds = ob.RealVectorBounds(2)
    bounds.setLow(0.0)
    bounds.setHigh(1.8)
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    checker = Clearance(si)
    si.setStateValidityChecker(checker)
    si.setup()
    for e in study.experiments:
        path = np.asarray(e["planned_path"])
        p = og.PathGeometric(si)
        for x, y, _ in path:
            s = space.allocState()
            s[0], s[1] = x, y
            p.append(s)
        assert ompl_smoothness(path) == pytest.approx(p.smoothness(), rel=1e-12)
        assert ompl_clearance(env, path) == pytest.approx(p.clearance(), rel=1e-12)
        assert p.length() == pytest.approx(np.hypot(*np.diff(path[:, :2], axis=0).T).sum(), rel=1e-12)


def test_the_export_has_omplss_tables_as_its_script_creates_them(study, ompl_db, tmp_path):
    export_ompl(study, tmp_path / "s.db")
    for table in ("experiments", "plannerConfigs", "enums", "runs", "progress"):
        ours = {r[1]: (r[2], r[5]) for r in query(tmp_path / "s.db", f"PRAGMA table_info({table})")}
        theirs = {r[1]: (r[2], r[5]) for r in query(ompl_db, f"PRAGMA table_info({table})")}
        base = {"runs": ("id", "experimentid", "plannerid"), "progress": ("runid", "time")}.get(table, theirs)
        assert {c: theirs[c] for c in base} == {c: ours[c] for c in base}, table
        shared = set(ours) & set(theirs)  # OMPL's run properties twb writes have OMPL's types
        assert {c: ours[c] for c in shared} == {c: theirs[c] for c in shared}, table
    ompl_status = query(ompl_db, "SELECT value, description FROM enums WHERE name = 'status' ORDER BY value")
    assert ompl_status == list(enumerate(OMPL_201_STATUS[:len(ompl_status)]))


def test_appending_to_omplss_real_database_and_ompls_script_appending_to_ours(study, ompl_db, tmp_path):
    db = tmp_path / "ompl.db"
    db.write_bytes(ompl_db.read_bytes())
    before = table_rows(db)
    assert len(before["runs"]) == 6 and len(before["progress"]) > 0  # RRT* reported its progress
    done = export_ompl(study, db, mode="append")
    assert_kept(before, table_rows(db))
    assert done.runs_before == 6 and done.version.startswith("OMPL ") and done.experiments == {"room-A": "room-A"}
    # the example's state clearance is the export's: the two planners' solution_clearance are one quantity
    clearance = dict(query(db, "SELECT p.name LIKE 'geometric_%', avg(r.solution_clearance) FROM runs r "
                               "JOIN plannerConfigs p ON p.id = r.plannerid GROUP BY 1"))
    assert all(0.045 < c < 0.5 for c in clearance.values()) and len(clearance) == 2
    # the other way round: twb's database first, OMPL's log appended by its own script
    ours = tmp_path / "ours.db"
    export_ompl(study, ours, version=done.version)
    mine = table_rows(ours)
    r = subprocess.run([sys.executable, "-m", "ompl.ompl_benchmark_statistics", "-a", "-d", str(ours),
                        str(ompl_db.with_name("room-A.log"))], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert_kept(mine, table_rows(ours))
    assert query(ours, "SELECT count(*) FROM runs") == [(26,)]
    assert query(ours, "SELECT count(DISTINCT name), count(DISTINCT version) FROM experiments") == [(1, 1)]


@pytest.mark.slow
def test_planner_arena_loads_and_plots_both(study, ompl_db, tmp_path):
    pytest.importorskip("plannerarena", reason="the plannerarena package is not installed (pip install -e '.[ompl]')")
    import matplotlib

    matplotlib.use("Agg")
    import plotnine as p9
    import polars as pl
    from plannerarena.database import load_database
    from plannerarena.performance import boxplot, enums_plot

    db = tmp_path / "ompl.db"
    db.write_bytes(ompl_db.read_bytes())
    export_ompl(study, db, mode="append")
    data = load_database(db)
    assert data["problem_names"] == ["room-A"] and data["parameters"] == []  # no problem parameter of twb's
    version = data["experiments"]["version"].unique().to_list()
    assert len(version) == 1
    # the Performance page: the runs of the problem and version, every planner of both
    runs = data["runs"].filter((pl.col("experiment") == "room-A") & (pl.col("version") == version[0]))
    planners = set(runs["planner"].cast(pl.String).to_list())
    assert planners == {"RRTConnect", "RRTstar", "fmm_sim", "fmm_twb", "prm_sim", "prm_twb"}
    for attr in ("time", "solution length", "solution smoothness", "solution clearance", "twb length m"):
        assert attr in data["attributes"]
        boxplot(runs, attr, [], "o", False).draw()
    twb = runs.filter(pl.col("planner").cast(pl.String) == "fmm_twb")
    assert twb.height == REPS and twb["time"].drop_nulls().n_unique() == 4  # a box of its runs' times
    status = data["enums"].filter(pl.col("name") == "status")
    enums_plot(runs, status, []).draw()
    charted = runs.join(status, left_on="status", right_on="value")
    assert charted.height == runs.height == 26  # every run in the status chart: none vanishes
    # twb's outcome is an enum of its own, which Planner Arena does not take for the status chart
    assert "twb outcome" in data["attributes"]
    assert data["enums"].filter(pl.col("name") == "twb outcome").is_empty()
    # the Progress page: OMPL's anytime planner's curve fits (loess, as Planner Arena draws it); twb adds no rows
    progress = data["progress"].join(runs.select("id", "planner"), left_on="runid", right_on="id")
    assert set(progress["planner"].cast(pl.String).to_list()) == {"RRTstar"}
    (p9.ggplot(progress, p9.aes(x="time", y="best cost", color="planner", fill="planner"))
     + p9.geom_smooth(na_rm=True, method="loess", span=0.1, se=False)).draw()
    # twb's database alone: its Performance page as above, an empty Progress page (nothing to fit)
    export_ompl(study, tmp_path / "twb.db")
    alone = load_database(tmp_path / "twb.db")
    assert alone["progress"].is_empty() and alone["runs"].height == 20
    boxplot(alone["runs"], "time", [], "o", False).draw()
    enums_plot(alone["runs"], alone["enums"].filter(pl.col("name") == "status"), []).draw()
