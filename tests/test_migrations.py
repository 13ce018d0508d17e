"""Alembic migrations: they build exactly the models' schema and keep data across upgrades; they live at the
repository's top level (alembic/) and `alembic upgrade head` from there builds the schema too."""

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.migration import MigrationContext

from server.core.db import MIGRATIONS, make_engine, migrate
from server.models import Base

ROOT = Path(__file__).resolve().parents[1]
ALEMBIC = Path(sys.executable).with_name("alembic")


def config(url: str) -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", MIGRATIONS)
    cfg.set_main_option("sqlalchemy.url", url)
    return cfg


def test_migrations_match_the_models(database_url):
    engine = make_engine(database_url)
    migrate(engine)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == []
    migrate(engine)  # idempotent


def test_a_checkout_migrates_from_its_top_level_alembic_directory():
    assert Path(MIGRATIONS) == ROOT / "alembic"
    assert (ROOT / "alembic" / "env.py").is_file() and not (ROOT / "alembic" / "__init__.py").exists()
    assert not (ROOT / "server" / "migrations").exists()


@pytest.mark.slow
def test_alembic_upgrade_head_from_the_repository_root(tmp_path):
    """The command line as docs/server.md shows it: alembic.ini at the root, the URL from TWB_DATABASE_URL."""
    from alembic.script import ScriptDirectory

    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    env = {**os.environ, "TWB_DATABASE_URL": url}
    out = subprocess.run([str(ALEMBIC), "upgrade", "head"], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    engine = make_engine(url)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
        version = MigrationContext.configure(conn).get_current_revision()
    engine.dispose()
    assert diff == []
    assert version == ScriptDirectory(MIGRATIONS).get_current_head()
    current = subprocess.run([str(ALEMBIC), "current"], cwd=ROOT, env=env, capture_output=True, text=True,
                             timeout=120)
    assert current.returncode == 0 and f"{version} (head)" in current.stdout, current.stderr


def test_the_alembic_directory_does_not_shadow_the_library():
    """From the repository root (the current directory first on sys.path) `alembic` is still the library."""
    out = subprocess.run([sys.executable, "-c", "import alembic, alembic.command; print(alembic.__file__)"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    where = Path(out.stdout.strip())
    assert where.name == "__init__.py" and not where.is_relative_to(ROOT / "alembic"), where


def test_upgrade_from_the_first_revision_keeps_data(tmp_path):
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    command.upgrade(config(url), "0001")
    con = sqlite3.connect(tmp_path / "db.sqlite")
    con.execute("insert into users (id, name, is_admin, created_at) values (1, 'old', 0, '2026-01-01')")
    con.execute("insert into runs (id, experiment_id, mode, repetition, status, seed, attempt, metrics, error, created_at)"
                " values (7, 1, 'sim', 1, 'completed', 0, 1, '{}', '', '2026-01-01')")
    con.execute("insert into messages (run_id, t, direction, line) values (7, 1.5, '>', 'T,T,Q')")
    con.commit()
    con.close()
    migrate(make_engine(url))
    con = sqlite3.connect(tmp_path / "db.sqlite")
    assert con.execute("select name from users").fetchall() == [("old",)]
    assert con.execute("select t, t_estimated, line from messages").fetchall() == [(1.5, 0, "T,T,Q")]
    assert con.execute("select version_num from alembic_version").fetchall() == [("0016",)]


def _old_run(c, mode: str) -> None:  # type: ignore[no-untyped-def]
    """A user, an experiment, its run 7 of ``mode`` and one pose of it (t 0.5 s at (0.3, 0.3)), in the columns
    every revision since 0009 has."""
    from sqlalchemy import text

    c.execute(text("insert into users (id, name, is_admin, created_at) values (1, 'old', false, '2026-01-01')"))
    c.execute(text(
        "insert into experiments (id, owner_id, status, environment, environment_data, start, goal, planner_params,"
        " modes, repetitions, seed, field, robot_radius, planning_info, error, created_at) values (1, 1, 'completed',"
        " 'room', '{}', '[0.3, 0.3]', '[1.5, 1.5]', '{}', :modes, 1, 0, 'sub', 0.045, '{}', '', '2026-01-01')"),
        {"modes": f'["{mode}"]'})
    c.execute(text("insert into runs (id, experiment_id, mode, repetition, status, seed, attempt, metrics, error,"
                   " created_at) values (7, 1, :mode, 1, 'completed', 0, 1, '{}', '', '2026-01-01')"), {"mode": mode})
    c.execute(text("insert into poses (run_id, t, x, y, theta) values (7, 0.5, 0.3, 0.3, 0.0)"))


def test_multi_robot_migration_up_and_down_keeps_data(database_url):
    """0010 (an experiment's robots, a pose's fleet member) on both databases: old rows get NULL, fleet rows
    are written and read, and the downgrade keeps every other column's data."""
    from sqlalchemy import inspect, text

    cfg = config(database_url)
    command.upgrade(cfg, "0009")
    engine = make_engine(database_url)
    with engine.begin() as c:
        _old_run(c, "sim")
    command.upgrade(cfg, "0010")
    with engine.begin() as c:
        assert c.execute(text("select robots from experiments")).all() == [(None,)]
        assert c.execute(text("select t, x, robot from poses")).all() == [(0.5, 0.3, None)]
        c.execute(text("update experiments set robots = :r"), {"r": '[{"start": [0.3, 0.3], "goal": [1.5, 1.5]}]'})
        c.execute(text("insert into poses (run_id, t, x, y, theta, robot) values (7, 1.0, 0.4, 0.3, 0.0, 3)"))
        assert c.execute(text("select robot from poses order by t")).all() == [(None,), (3,)]
    engine.dispose()
    command.downgrade(cfg, "0009")
    engine = make_engine(database_url)
    cols = {t: {c["name"] for c in inspect(engine).get_columns(t)} for t in ("experiments", "poses")}
    assert "robots" not in cols["experiments"] and "robot" not in cols["poses"]
    with engine.begin() as c:
        assert c.execute(text("select t, x from poses order by t")).all() == [(0.5, 0.3), (1.0, 0.4)]
        assert c.execute(text("select environment, start from experiments")).all()[0][0] == "room"
    engine.dispose()
    command.upgrade(cfg, "head")


def test_obstacle_poses_migration_up_and_down(database_url):
    """0011 (an obstacle robot's poses beside the run's) on both databases: old rows get NULL and stay the run's,
    obstacle rows are written and kept apart, and the downgrade drops them (they would read as the robot's own)
    and keeps every other row."""
    from sqlalchemy import inspect, text

    from server.core.db import make_session_factory
    from server.store.poses import obstacle_poses, run_poses

    cfg = config(database_url)
    command.upgrade(cfg, "0010")
    engine = make_engine(database_url)
    with engine.begin() as c:
        _old_run(c, "twb")
    command.upgrade(cfg, "0011")
    with engine.begin() as c:
        assert c.execute(text("select t, x, obstacle from poses")).all() == [(0.5, 0.3, None)]
        c.execute(text("insert into poses (run_id, t, x, y, theta, obstacle) values (7, 0.5, 1.2, 0.9, 0.0, 0)"))
    with make_session_factory(engine)() as s:
        assert run_poses(s, 7) == [[0.5, 0.3, 0.3, 0.0]] and obstacle_poses(s, 7) == {0: [[0.5, 1.2, 0.9, 0.0]]}
    engine.dispose()
    command.downgrade(cfg, "0010")
    engine = make_engine(database_url)
    assert "obstacle" not in {c["name"] for c in inspect(engine).get_columns("poses")}
    with engine.begin() as c:
        assert c.execute(text("select t, x from poses")).all() == [(0.5, 0.3)]
    engine.dispose()
    command.upgrade(cfg, "head")


def test_poses_lose_their_row_check_and_keep_their_cascade(database_url):
    """0012 on both databases: the poses' foreign key goes (its per-row check was most of what storing poses
    cost PostgreSQL), a trigger still deletes a run's poses with it, directly or through its experiment; the
    downgrade drops orphan poses and brings the key back, which refuses a pose of no run."""
    import pytest
    from sqlalchemy import inspect, text
    from sqlalchemy.exc import IntegrityError

    cfg = config(database_url)
    command.upgrade(cfg, "0011")
    engine = make_engine(database_url)
    with engine.begin() as c:
        _old_run(c, "sim")
    command.upgrade(cfg, "0012")
    assert inspect(engine).get_foreign_keys("poses") == []
    with engine.begin() as c:
        c.execute(text("insert into runs (id, experiment_id, mode, repetition, status, seed, attempt, metrics, error,"
                       " created_at) values (8, 1, 'sim', 2, 'completed', 0, 1, '{}', '', '2026-01-01')"))
        c.execute(text("insert into poses (run_id, t, x, y, theta) values (8, 0.5, 1.0, 1.0, 0.0), "
                       "(8, 0.6, 1.1, 1.0, 0.0), (99, 0.5, 2.0, 2.0, 0.0)"))  # 99: a run that is not there
        c.execute(text("delete from runs where id = 8"))
        assert c.execute(text("select run_id, x from poses order by run_id")).all() == [(7, 0.3), (99, 2.0)]
        c.execute(text("delete from experiments where id = 1"))  # cascades to run 7, and the trigger to its pose
        assert c.execute(text("select run_id from poses")).all() == [(99,)]
    engine.dispose()
    command.downgrade(cfg, "0011")
    engine = make_engine(database_url)
    assert [fk["referred_table"] for fk in inspect(engine).get_foreign_keys("poses")] == ["runs"]
    with engine.begin() as c:
        assert c.execute(text("select count(*) from poses")).scalar() == 0
    with pytest.raises(IntegrityError), engine.begin() as c:
        c.execute(text("insert into poses (run_id, t, x, y, theta) values (99, 0.5, 2.0, 2.0, 0.0)"))
    engine.dispose()
    command.upgrade(cfg, "head")


def test_label_and_problem_migration_names_old_experiments(database_url):
    """0014 on both databases: old experiments get the names a job gets by default (the planner without the
    parameters, which their rows keep with the defaults filled in; a plan of the environment's; the start and
    goal to the cm; a fleet's robot count), and the downgrade drops the columns and keeps the rest."""
    from alembic.script import ScriptDirectory
    from sqlalchemy import inspect, text

    cfg = config(database_url)
    before = ScriptDirectory.from_config(cfg).get_revision("0014").down_revision
    assert before == "0013"
    command.upgrade(cfg, before)
    engine = make_engine(database_url)
    env = '{"name": "room", "plans": [{"name": "A", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708]}]}'
    with engine.begin() as c:
        _old_run(c, "sim")  # experiment 1: no planner (an explicit path) from (0.3, 0.3) to (1.5, 1.5)
        for i, (planner, start, goal, extra) in enumerate([
                ("fm2", "[0.3, 0.3, 0.0]", "[1.5, 1.5, 1.5708]", {}),
                ("fmm", "[0.3, 0.3]", "[1.5, 1.5, 1.5708]", {"controller": "pure_pursuit",
                                                           "profile_overrides": '{"tracker_noise_xy_m": 0.003}'}),
                ("prioritized", "[0.3, 0.3]", "[1.5, 1.5]", {"robots": '[{"start": [0.3, 0.3], "goal": [1, 1]}, '
                                                                       '{"start": [1, 1], "goal": [0.3, 0.3]}]'})],
                start=2):
            cols = ", ".join(extra)
            c.execute(text(
                "insert into experiments (id, owner_id, status, environment, environment_data, start, goal, planner,"
                " planner_params, modes, repetitions, seed, field, robot_radius, planning_info, error, created_at"
                f"{', ' + cols if cols else ''}) values (:id, 1, 'completed', 'room', :env, :start, :goal, :planner,"
                " '{\"samples\": 3}', '[\"sim\"]', 1, 0, 'sub', 0.045, '{}', '', '2026-01-01'"
                f"{''.join(', :' + k for k in extra)})"),
                {"id": i, "env": env, "start": start, "goal": goal, "planner": planner, **extra})
    command.upgrade(cfg, "0014")
    with engine.begin() as c:
        assert c.execute(text("select id, label, problem from experiments order by id")).all() == [
            (1, "explicit path", "room (0.30,0.30)→(1.50,1.50)"),
            (2, "fm2", "room A"),
            (3, "fmm/pure_pursuit · tracker_noise_xy_m=0.003", "room (0.30,0.30)→(1.50,1.50)"),  # no heading: not A
            (4, "prioritized", "room 2 robots")]
    engine.dispose()
    command.downgrade(cfg, before)
    engine = make_engine(database_url)
    assert not {"label", "problem"} & {c["name"] for c in inspect(engine).get_columns("experiments")}
    with engine.begin() as c:
        assert c.execute(text("select count(*) from experiments")).scalar() == 4


def test_run_clock_migration_up_and_down(database_url):
    """0015 on both databases: old runs record no clock or time scale (NULL); new ones are written and read; the
    downgrade drops both columns and keeps the runs."""
    from sqlalchemy import inspect, text

    cfg = config(database_url)
    command.upgrade(cfg, "0014")
    engine = make_engine(database_url)
    with engine.begin() as c:
        _old_run(c, "sim")
    command.upgrade(cfg, "0015")
    with engine.begin() as c:
        assert c.execute(text("select clock, time_scale from runs where id = 7")).one() == (None, None)
        c.execute(text("update runs set clock = 'lockstep', time_scale = 5.0 where id = 7"))
        assert c.execute(text("select clock, time_scale from runs where id = 7")).one() == ("lockstep", 5.0)
    engine.dispose()
    command.downgrade(cfg, "0014")
    engine = make_engine(database_url)
    assert not {"clock", "time_scale"} & {c["name"] for c in inspect(engine).get_columns("runs")}
    with engine.begin() as c:
        assert c.execute(text("select count(*) from runs")).scalar() == 1
    engine.dispose()


def test_run_planning_progress_migration_up_and_down(database_url):
    """0016 on both databases: old runs have no planning progress of their own (NULL); a curve is written and read
    back as JSON; the downgrade drops the column and keeps the runs."""
    from sqlalchemy import inspect, text

    cfg = config(database_url)
    command.upgrade(cfg, "0015")
    engine = make_engine(database_url)
    with engine.begin() as c:
        _old_run(c, "twb")
    command.upgrade(cfg, "0016")
    with engine.begin() as c:
        assert c.execute(text("select planning_progress from runs where id = 7")).one() == (None,)
        c.execute(text("update runs set planning_progress = :p where id = 7"), {"p": "[[0.01, 2.5], [0.2, 2.31]]"})
        got = c.execute(text("select planning_progress from runs where id = 7")).scalar()
        assert (json.loads(got) if isinstance(got, str) else got) == [[0.01, 2.5], [0.2, 2.31]]
    engine.dispose()
    command.downgrade(cfg, "0015")
    engine = make_engine(database_url)
    assert "planning_progress" not in {c["name"] for c in inspect(engine).get_columns("runs")}
    with engine.begin() as c:
        assert c.execute(text("select count(*) from runs")).scalar() == 1
    engine.dispose()


def test_per_run_plans_migration_up_and_down(database_url):
    """0013 on both databases: old runs get no plan of their own (NULL: their experiment's was theirs), old
    experiments and programs are deterministic; a run's planner seed (63 bits), plan and planning are written
    and read; the downgrade drops them and keeps every other column's data."""
    from sqlalchemy import inspect, text

    cfg = config(database_url)
    command.upgrade(cfg, "0012")
    engine = make_engine(database_url)
    with engine.begin() as c:
        _old_run(c, "sim")
        c.execute(text("insert into programs (id, owner_id, name, kind, args, content, size, sha256, created_at) "
                       "values (1, 1, 'p', 'python', '[]', :content, 1, 'x', '2026-01-01')"), {"content": b"x"})
    command.upgrade(cfg, "0013")
    with engine.begin() as c:
        assert c.execute(text("select planner_seed, planned_path, planning_time_s, planning_cpu_s, planning_repeats,"
                              " planning_load from runs")).all() == [(None,) * 6]
        assert c.execute(text("select planner_seed, planner_stochastic from experiments")).all() == [(None, False)]
        assert c.execute(text("select stochastic from programs")).all() == [(False,)]
        c.execute(text("update runs set planner_seed = :s, planned_path = :p, planning_time_s = 0.0125, "
                       "planning_cpu_s = 0.011, planning_repeats = 4, planning_load = 0.5"),
                  {"s": 2**63 - 1, "p": "[[0.3, 0.3, 0.0], [1.5, 1.5, 1.5708]]"})
        c.execute(text("update experiments set planner_seed = 7, planner_stochastic = true"))
        assert c.execute(text("select planner_seed, planning_repeats, planning_load from runs")).all() == \
            [(2**63 - 1, 4, 0.5)]
    engine.dispose()
    command.downgrade(cfg, "0012")
    engine = make_engine(database_url)
    cols = {t: {c["name"] for c in inspect(engine).get_columns(t)} for t in ("runs", "experiments", "programs")}
    assert not cols["runs"] & {"planner_seed", "planned_path", "planning_time_s", "planning_cpu_s",
                               "planning_repeats", "planning_load"}
    assert not cols["experiments"] & {"planner_seed", "planner_stochastic"} and "stochastic" not in cols["programs"]
    with engine.begin() as c:
        assert c.execute(text("select id, mode, seed, status from runs")).all() == [(7, "sim", 0, "completed")]
        assert c.execute(text("select t, x from poses")).all() == [(0.5, 0.3)]
        assert c.execute(text("select name from programs")).all() == [("p",)]
    engine.dispose()
    command.upgrade(cfg, "head")
