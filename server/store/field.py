"""Robots and sub-fields as stored: registrations survive restarts, sub-field states are mirrored."""

from __future__ import annotations

from typing import Optional

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from ..models import Robot, Subfield, Token, utcnow
from ..schemas import RobotRegister
from ..status import RobotStatus, SubfieldState

__all__ = ["load_robots", "reset_subfields", "save_robot", "save_subfield"]


def save_robot(session: Session, body: RobotRegister, *, token_id: Optional[int]) -> None:
    """Add or refresh a robot's registration, by the token ``token_id`` (None: in the server's process)."""
    row = session.scalar(select(Robot).where(Robot.robot_id == body.robot_id))
    if row is None:
        row = Robot(robot_id=body.robot_id)
        session.add(row)
    for k in ("host", "port", "platform", "backend", "profile", "origin", "area"):
        setattr(row, k, getattr(body, k))
    row.token_id = token_id
    row.status = RobotStatus.IDLE
    row.last_seen = utcnow()


def load_robots(session: Session) -> list[tuple[Robot, Optional[str]]]:
    """Every robot registered at some time, with the hash of the token that registered it (if it still exists)."""
    q = select(Robot, Token.token_hash).outerjoin(Token, Robot.token_id == Token.id)
    return [(r, h) for r, h in session.execute(q)]


def save_subfield(session: Session, k: int, *, state: str, environment: Optional[str], run_id: Optional[int],
                  robot_id: Optional[str]) -> None:
    """Mirror sub-field ``k``'s state."""
    row = session.get(Subfield, k)
    row.state, row.environment, row.run_id, row.robot_id = state, environment, run_id, robot_id
    row.updated_at = utcnow()


def reset_subfields(session: Session) -> None:
    """All four sub-fields exist and are idle with nothing built (at start-up)."""
    for i in range(1, 5):
        if session.get(Subfield, i) is None:
            session.add(Subfield(id=i))
    session.execute(update(Subfield).values(state=SubfieldState.IDLE, run_id=None, robot_id=None, environment=None))
