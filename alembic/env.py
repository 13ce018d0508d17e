"""Alembic environment: the database URL comes from the server settings (``TWB_*``).

The server calls migrations itself at start-up with an open connection
(``server.core.db.migrate``); ``alembic upgrade head`` from the repository
root also works (alembic.ini) and reads ``TWB_DATABASE_URL`` / ``TWB_DATA_DIR``.
This directory is installed as ``server/migrations`` by the wheel
(pyproject.toml), never as a top-level ``alembic``: it has no ``__init__.py``,
so it cannot shadow the Alembic library from the repository root either.
"""

from __future__ import annotations

from alembic import context
from sqlalchemy import engine_from_config, pool

from server.models import Base

config = context.config
target_metadata = Base.metadata


def run_offline() -> None:
    context.configure(url=_url(), target_metadata=target_metadata, literal_binds=True, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


def _url() -> str:
    url = config.get_main_option("sqlalchemy.url")
    if url:
        return url
    from server.core.settings import Settings

    return Settings().database_url


def run_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()
        return
    engine = engine_from_config({"sqlalchemy.url": _url()}, prefix="sqlalchemy.", poolclass=pool.NullPool)
    with engine.connect() as conn:
        context.configure(connection=conn, target_metadata=target_metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
