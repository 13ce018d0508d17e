"""Alembic migrations: they build exactly the models' schema and keep data across upgrades."""

import sqlite3

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.migration import MigrationContext

from server.core.db import MIGRATIONS, make_engine, migrate
from server.models import Base


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
    assert con.execute("select version_num from alembic_version").fetchall() == [("0009",)]
