"""Who may see what: a user's own rows (admins see everything), visible environments.

Rows of other users answer exactly like rows that do not exist
(:class:`~server.errors.NotFound`): nobody learns that they exist.
"""

from __future__ import annotations

from typing import Any, Optional, TypeVar

from sqlalchemy import ColumnElement, or_, select, true
from sqlalchemy.orm import Session

from .core.security import Principal
from .errors import NotFound
from .models import Environment, Experiment, Program, Run

__all__ = ["environment_named", "event_for", "hidden_subfield_runs", "owned", "visible_environments"]

Row = TypeVar("Row", Experiment, Program, Run)


def owned(session: Session, user: Principal, model: type[Row], row_id: int, what: str) -> Row:
    """The ``model`` row ``row_id`` if ``user`` owns it (runs: through their experiment) or is an admin.

    Raises :class:`NotFound` ("<what> not found") otherwise.
    """
    q = select(model)
    owner: Any = model.owner_id if model is not Run else Experiment.owner_id
    if model is Run:
        q = q.join(Experiment, Run.experiment_id == Experiment.id)
    q = q.where(model.id == row_id)
    if not user.is_admin:
        q = q.where(owner == user.id)
    row = session.scalar(q)
    if row is None:
        raise NotFound(f"{what} not found")
    return row


def environment_named(session: Session, user: Principal, name: str) -> Optional[Environment]:
    """The environment ``name`` means for ``user``: their own, else the built-in one (names of built-ins
    are reserved, so at most one of these exists); an admin may also name another user's (the oldest)."""
    rows = session.scalars(select(Environment).where(Environment.name == name, visible_environments(user))
                           .order_by(Environment.id)).all()
    mine = [r for r in rows if r.owner_id == user.id]
    builtin = [r for r in rows if r.builtin]
    return (mine or builtin or rows or [None])[0]


def visible_environments(user: Principal) -> ColumnElement[bool]:
    """SQL condition: environments a user may see (built-ins and their own; admins see all)."""
    if user.is_admin:
        return true()
    return or_(Environment.builtin.is_(True), Environment.owner_id == user.id)


def hidden_subfield_runs(user: Principal, owner_id: Optional[int], last_owner_id: Optional[int]) -> dict[str, None]:
    """The run fields of a sub-field ``user`` may not see, set to None: its current run (``run_id``, of
    ``owner_id``) and its last run since the start (``last_run_id``, of ``last_owner_id``) unless they are the
    user's; admins see both."""
    if user.is_admin:
        return {}
    return {k: None for k, owner in (("run_id", owner_id), ("last_run_id", last_owner_id)) if owner != user.id}


def event_for(user: Principal, event: dict[str, Any]) -> Optional[dict[str, Any]]:
    """A live event as ``user`` may see it (None: not at all); admins see everything.

    Experiments and runs: only one's own.  Robot positions: of robots that
    run nobody's run or one's own (another user's run is not followed live).
    Sub-fields: another user's run is not named.  Nobody sees who owns what.
    """
    if user.is_admin:
        return event
    owner = event.get("owner_id")
    mine = owner == user.id
    kind = event.get("type")
    if kind in ("experiment", "run") or (kind == "pose" and event.get("run_id") is not None):
        return event if mine else None
    shown = {k: v for k, v in event.items() if k not in ("owner_id", "last_owner_id")}
    if kind == "subfield":
        hide = {k: v for k, v in hidden_subfield_runs(user, owner, event.get("last_owner_id")).items()
                if shown["subfield"].get(k) is not None}
        if hide:
            shown["subfield"] = {**shown["subfield"], **hide}
    return shown
