"""A run's logged poses: the one query for them, and the bulk insert of tracker batches and run ends.

A multi-robot run's poses carry the fleet member they belong to (``robot``,
its index in the job's ``robots``); a single robot's have none (NULL).
A field run's obstacle robots' tracker poses are stored in the same table
with the obstacle's index in the environment's ``moving_obstacles``
(``obstacle``); the run's own poses have none, and :func:`run_poses` reads
only those.
"""

from __future__ import annotations

import struct
import threading
from typing import Any, Optional, Sequence

import numpy as np
from sqlalchemy import Engine, PoolProxiedConnection, select
from sqlalchemy.orm import Session

from ..models import Pose
from .driver import as_sqlalchemy_errors

__all__ = ["add_obstacle_poses", "add_poses", "insert_poses", "obstacle_poses", "run_poses"]

_COLUMNS = "run_id, t, x, y, theta"

_EPS = 1e-9


def run_poses(session: Session, run_id: int, *, after_t: Optional[float] = None,
              between: Optional[tuple[Optional[float], Optional[float]]] = None, robot: Optional[int] = None,
              fleet: bool = False) -> list[list[float]]:
    """Poses ``[t, x, y, theta]`` (s, m, m, rad) of a run, oldest first.

    ``after_t``: only later than this experiment time.  ``between``: only
    within ``(t_start, t_end)`` (inclusive, 1 ns slack) when both are known.
    ``robot``: only this fleet member's.  ``fleet``: a multi-robot run's rows
    ``[t, x, y, theta, robot]``, robot by robot, each oldest first.
    """
    cols = (Pose.t, Pose.x, Pose.y, Pose.theta) + ((Pose.robot,) if fleet else ())
    q = select(*cols).where(Pose.run_id == run_id, Pose.obstacle.is_(None))
    if after_t is not None:
        q = q.where(Pose.t > after_t)
    if between is not None and between[0] is not None and between[1] is not None:
        q = q.where(Pose.t >= between[0] - _EPS, Pose.t <= between[1] + _EPS)
    if robot is not None:
        q = q.where(Pose.robot == robot)
    order = (Pose.robot, Pose.t) if fleet else (Pose.t,)
    return [list(r) for r in session.execute(q.order_by(*order))]


def obstacle_poses(session: Session, run_id: int) -> dict[int, list[list[float]]]:
    """A field run's stored obstacle-robot poses: per obstacle index (the environment's
    ``moving_obstacles[k]``) its ``[t, x, y, theta]`` rows (s, m, m, rad; the run's clock and frame), oldest
    first; empty when none are stored."""
    q = (select(Pose.obstacle, Pose.t, Pose.x, Pose.y, Pose.theta)
         .where(Pose.run_id == run_id, Pose.obstacle.is_not(None)).order_by(Pose.obstacle, Pose.t))
    out: dict[int, list[list[float]]] = {}
    for k, *row in session.execute(q):
        out.setdefault(k, []).append(row)
    return out


def insert_poses(engine: Engine, run_id: int, rows: np.ndarray, *, lock: threading.Lock) -> None:
    """Store ``rows`` ``(N, 4)`` (t, x, y, theta: s, m, m, rad) for ``run_id`` in one transaction, by the
    database's bulk path: PostgreSQL's ``COPY``, the driver's ``executemany`` elsewhere (no ORM per row).

    ``lock``: SQLite writes one at a time, queued on this mutex rather than on SQLite's sleeping busy
    handler; PostgreSQL takes concurrent writers.
    """
    with as_sqlalchemy_errors(engine.dialect, "INSERT INTO poses"):
        conn = engine.raw_connection()
        try:
            if engine.dialect.name == "postgresql":
                _copy(conn.driver_connection, run_id, rows)
            else:
                with lock:
                    _executemany(conn, engine.dialect.paramstyle, run_id, rows)
            conn.commit()
        except Exception as exc:
            _roll_back_or_drop(conn, exc)
            raise
        finally:
            conn.close()


def _roll_back_or_drop(conn: PoolProxiedConnection, exc: BaseException) -> None:
    """Roll back a raw pooled connection after ``exc``; one that ``exc`` cut (the database went away mid-COPY)
    is dropped from the pool instead: rolling it back, or the pool's reset on its return, only fails again
    (and the pool logs that reset's traceback)."""
    try:
        conn.rollback()
    except Exception:
        conn.invalidate(exc)


def add_poses(session: Session, run_id: int, rows: np.ndarray) -> None:
    """Store ``rows`` for ``run_id`` inside the session's transaction (a run's end written at once: its poses,
    log and status commit together), by the same bulk paths: ``(N, 4)`` (t, x, y, theta: s, m, m, rad) of one
    robot, or ``(N, 5)`` with the fleet member's index last (a multi-robot run)."""
    _add(session, run_id, rows, "robot" if _has_index(rows) else None)


def add_obstacle_poses(session: Session, run_id: int, tracks: Sequence[np.ndarray]) -> None:
    """Store a field run's obstacle-robot poses inside the session's transaction, by the same bulk paths:
    ``tracks[k]`` ``(T, 4)`` (t, x, y, theta: s, m, m, rad) of the environment's ``moving_obstacles[k]``."""
    parts = [np.column_stack([np.asarray(tr, dtype=float).reshape(-1, 4), np.full(len(tr), k)])
             for k, tr in enumerate(tracks)]
    _add(session, run_id, np.concatenate(parts) if parts else np.zeros((0, 5)), "obstacle")


def _add(session: Session, run_id: int, rows: np.ndarray, index: Optional[str]) -> None:
    """Insert ``rows`` in the session's transaction; ``index``: the column of their fifth (``robot`` or
    ``obstacle``), None for four columns."""
    if len(rows) == 0:
        return
    conn = session.connection()
    if conn.dialect.name == "postgresql":
        with as_sqlalchemy_errors(conn.dialect, "COPY poses"):
            _copy(conn.connection.driver_connection, run_id, rows, index)
    else:
        conn.exec_driver_sql(_insert_sql(conn.dialect.paramstyle, index), _tuples(run_id, rows))


def _has_index(rows: np.ndarray) -> bool:
    """Rows with an index (a fleet member's, an obstacle's) as a fifth column."""
    return rows.ndim == 2 and rows.shape[1] == 5


def _columns(index: Optional[str]) -> str:
    return _COLUMNS if index is None else f"{_COLUMNS}, {index}"


def _copy(pg: object, run_id: int, rows: np.ndarray, index: Optional[str] = None) -> None:
    columns = _columns(index)
    with pg.cursor() as cur:  # type: ignore[attr-defined]
        with cur.copy(f"COPY poses ({columns}) FROM STDIN (FORMAT BINARY)") as copy:
            copy.write(binary_copy(run_id, rows))


#: PostgreSQL's binary COPY: its signature, flags and header extension length; the end of the data
_PGCOPY_HEAD = b"PGCOPY\n\xff\r\n\x00" + struct.pack("!ii", 0, 0)
_PGCOPY_TAIL = b"\xff\xff"


def binary_copy(run_id: int, rows: np.ndarray) -> bytes:
    """``rows`` ``(N, 4)`` (t, x, y, theta: s, m, m, rad), or ``(N, 5)`` with an index last, as the data of a
    binary ``COPY poses (run_id, t, x, y, theta[, index])``: per row the field count, then each field's
    length and big-endian value (int4, float8 x 4[, int4]).  Built in numpy, about 9x less CPU than
    formatting the rows as text, and exact (the doubles go as they are)."""
    indexed = _has_index(rows)
    fields = [("n", ">i2"), ("l_run", ">i4"), ("run", ">i4")]
    for name in ("t", "x", "y", "a"):
        fields += [(f"l_{name}", ">i4"), (name, ">f8")]
    if indexed:
        fields += [("l_k", ">i4"), ("k", ">i4")]
    out = np.empty(len(rows), np.dtype(fields))
    out["n"], out["l_run"], out["run"] = len(fields) // 2, 4, run_id
    for j, name in enumerate(("t", "x", "y", "a")):
        out[f"l_{name}"], out[name] = 8, rows[:, j]
    if indexed:
        out["l_k"], out["k"] = 4, rows[:, 4]
    return _PGCOPY_HEAD + out.tobytes() + _PGCOPY_TAIL


def _executemany(conn: object, paramstyle: str, run_id: int, rows: np.ndarray) -> None:
    cur = conn.cursor()  # type: ignore[attr-defined]
    try:
        cur.executemany(_insert_sql(paramstyle), _tuples(run_id, rows))
    finally:
        cur.close()


def _tuples(run_id: int, rows: np.ndarray) -> list[tuple[Any, ...]]:
    """The INSERT's parameters: ``(run_id, t, x, y, theta)`` per row, ``(..., index)`` for rows with a fifth
    column (a multi-robot run's robot, an obstacle robot's obstacle)."""
    if _has_index(rows):
        return [(run_id, t, x, y, a, int(k)) for t, x, y, a, k in rows.tolist()]
    return [(run_id, t, x, y, a) for t, x, y, a in rows.tolist()]


def _insert_sql(paramstyle: str, index: Optional[str] = None) -> str:
    """The poses INSERT for the driver's parameter style (a raw executemany is ~5x faster than the ORM's);
    ``index``: with that column (``robot``, ``obstacle``) last."""
    n = 5 if index is None else 6
    marks = {"qmark": "?", "format": "%s", "pyformat": "%s", "numeric": None, "named": None}.get(paramstyle, "?")
    if marks is None:
        params = ", ".join(f":{i}" if paramstyle == "numeric" else f":p{i}" for i in range(1, n + 1))
    else:
        params = ", ".join([marks] * n)
    return f"INSERT INTO poses ({_columns(index)}) VALUES ({params})"
