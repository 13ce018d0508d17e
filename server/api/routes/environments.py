"""Environments (docs/design.md, "Environment file"): the built-ins and users' own."""

from __future__ import annotations

from fastapi import APIRouter, Query
from sqlalchemy import func, select

from planners import InvalidEnvironment, parse_environment

from ...access import visible_environments
from ...errors import Conflict, Invalid, NotFound
from ...models import Environment, User
from ...schemas import EnvironmentCreate, EnvironmentPublic, Page
from ..deps import MAX_OFFSET, CurrentUser, NamePath, SessionDep
from ..responses import AUTHENTICATED, errors

router = APIRouter(prefix="/environments", tags=["environments"], responses=AUTHENTICATED)


def _public(row: Environment, owner: str | None) -> EnvironmentPublic:
    d = row.data
    return EnvironmentPublic(
        name=row.name, size=d["size"], blocks=d.get("blocks", []), plans=d.get("plans", []),
        description=d.get("description", ""), builtin=row.builtin, owner=owner,
    )


@router.get("", response_model=Page[EnvironmentPublic])
def list_environments(
    session: SessionDep,
    user: CurrentUser,
    offset: int = Query(default=0, ge=0, le=MAX_OFFSET),
    limit: int = Query(default=100, ge=1, le=1000),
) -> Page[EnvironmentPublic]:
    """Built-in environments and your own."""
    cond = visible_environments(user)
    q = select(Environment, User.name).outerjoin(User, Environment.owner_id == User.id).where(cond)
    rows = session.execute(q.order_by(Environment.id).offset(offset).limit(limit))
    count = session.scalar(select(func.count(Environment.id)).where(cond)) or 0
    return Page(data=[_public(e, owner) for e, owner in rows], count=count)


@router.get("/{name}", response_model=EnvironmentPublic, responses=errors(404))
def get_environment(name: NamePath, session: SessionDep, user: CurrentUser) -> EnvironmentPublic:
    """One environment by name."""
    row = session.execute(
        select(Environment, User.name).outerjoin(User, Environment.owner_id == User.id)
        .where(Environment.name == name, visible_environments(user))
    ).first()
    if row is None:
        raise NotFound("Environment not found")
    return _public(*row)


@router.post("", response_model=EnvironmentPublic, status_code=201, responses=errors(409, 413))
def create_environment(body: EnvironmentCreate, session: SessionDep, user: CurrentUser) -> EnvironmentPublic:
    """Add an environment (validated like an environment file); names are unique."""
    try:
        env = parse_environment(body.to_data())
    except InvalidEnvironment as exc:
        raise Invalid(str(exc)) from None
    if session.scalar(select(Environment).where(Environment.name == env.name)) is not None:
        raise Conflict(f"Environment {env.name!r} already exists")
    row = Environment(name=env.name, owner_id=user.id, builtin=False, data=env.to_dict())
    session.add(row)
    session.commit()
    return _public(row, user.name)
