"""The one query for a run's logged poses."""

from __future__ import annotations

from typing import Optional

from sqlalchemy import select
from sqlalchemy.orm import Session

from ..models import Pose

__all__ = ["run_poses"]

_EPS = 1e-9


def run_poses(session: Session, run_id: int, *, after_t: Optional[float] = None,
              between: Optional[tuple[Optional[float], Optional[float]]] = None) -> list[list[float]]:
    """Poses ``[t, x, y, theta]`` (s, m, m, rad) of a run, oldest first.

    ``after_t``: only later than this experiment time.  ``between``: only
    within ``(t_start, t_end)`` (inclusive, 1 ns slack) when both are known.
    """
    q = select(Pose.t, Pose.x, Pose.y, Pose.theta).where(Pose.run_id == run_id)
    if after_t is not None:
        q = q.where(Pose.t > after_t)
    if between is not None and between[0] is not None and between[1] is not None:
        q = q.where(Pose.t >= between[0] - _EPS, Pose.t <= between[1] + _EPS)
    return [list(r) for r in session.execute(q.order_by(Pose.t))]
