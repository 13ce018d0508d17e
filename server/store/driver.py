"""The database driver's own errors as SQLAlchemy's, where the bulk paths use the driver directly (COPY)."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from sqlalchemy.engine import Dialect
from sqlalchemy.exc import DBAPIError

__all__ = ["as_sqlalchemy_errors"]


@contextmanager
def as_sqlalchemy_errors(dialect: Dialect, statement: str) -> Iterator[None]:
    """Raise the driver's errors inside as :class:`~sqlalchemy.exc.DBAPIError` (``OperationalError`` ...), as
    SQLAlchemy raises them for its own statements: the callers handle those (an unreachable database is a
    503, a run's end waits for it, a run in flight is queued again), not a driver's ``psycopg`` error."""
    error = dialect.loaded_dbapi.Error
    try:
        yield
    except error as exc:
        raise DBAPIError.instance(statement, None, exc, error) from exc
