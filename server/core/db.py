"""Database engine, sessions and migrations.

SQLite runs in WAL mode with a busy timeout, so the API threads and the run
pipeline can write concurrently; Alembic migrations are applied automatically
when the server starts (``upgrade head``).  They live in the repository's
top-level ``alembic/`` directory (Alembic's standard layout, for ``alembic``
commands run from the repository root); the wheel carries that directory as
``server/migrations``, so an installed wheel migrates like a checkout.
"""

from __future__ import annotations

import os
from pathlib import Path

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.orm import Session, sessionmaker

__all__ = ["MIGRATIONS", "make_engine", "make_session_factory", "migrate", "private_sqlite_file"]


def _script_location() -> str:
    """The migrations' directory: ``server/migrations`` in an installed wheel, else the checkout's ``alembic/``."""
    server = Path(__file__).resolve().parents[1]
    packaged = server / "migrations"
    if (packaged / "env.py").is_file():
        return str(packaged)
    return str(server.parent / "alembic")


#: Alembic's script location (a directory path): the installed wheel's ``server/migrations``,
#: or ``alembic/`` at the root of a checkout (an editable install too)
MIGRATIONS = _script_location()


def make_engine(url: str) -> Engine:
    """Engine for ``url``; SQLite gets WAL, NORMAL sync, foreign keys and a 10 s busy timeout."""
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 10})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _record):  # type: ignore[no-untyped-def]
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=10000")
            cur.close()

        return engine
    # ten kept connections: the run pipeline's database threads, the dispatcher's and the API's can hold one
    # each at once; the default five opened and closed the rest under load (a new backend per transaction)
    return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)


def private_sqlite_file(url: str) -> None:
    """Create a SQLite database file readable by its owner only (0600), or make an existing one so.

    SQLite gives its ``-wal`` and ``-shm`` files the database file's mode.
    """
    if not url.startswith("sqlite:///") or url.endswith(":memory:"):
        return
    path = Path(url[len("sqlite:///"):])
    for p in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
        if p.exists():
            p.chmod(0o600)
    if not path.exists():
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT, 0o600))


def make_session_factory(engine: Engine) -> sessionmaker[Session]:
    return sessionmaker(engine, expire_on_commit=False)


def migrate(engine: Engine) -> None:
    """Bring the database schema to the newest Alembic revision."""
    from alembic import command
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", MIGRATIONS)
    cfg.set_main_option("sqlalchemy.url", engine.url.render_as_string(hide_password=False))
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "head")
