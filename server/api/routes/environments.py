"""Environments (DESIGN §3): the built-ins and users' own."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from sqlalchemy import func, or_, select

from planners import InvalidEnvironment, parse_environment

from ...core.security import Principal
from ...models import Environment, User
from ...schemas import EnvironmentCreate, EnvironmentPublic, Page
from ..deps import CurrentUser, SessionDep

router = APIRouter(prefix="/environments", tags=["environments"])


def _public(row: Environment, owner: str | None) -> EnvironmentPublic:
    d = row.data
    return EnvironmentPublic(
        name=row.name, size=d["size"], blocks=d.get("blocks", []), plans=d.get("plans", []),
        description=d.get("description", ""), builtin=row.builtin, owner=owner,
    )


def visible(user: Principal):  # type: ignore[no-untyped-def]
    """SQL condition: environments a user may see (built-ins, own; admins see all)."""
    if user.is_admin:
        return True
    return or_(Environment.builtin.is_(True), Environment.owner_id == user.id)


@router.get("", response_model=Page[EnvironmentPublic])
def list_environments(session: SessionDep, user: CurrentUser, offset: int = 0, limit: int = 100) -> Page[EnvironmentPublic]:
    """Built-in environments and your own."""
    cond = visible(user)
    q = select(Environment, User.name).outerjoin(User, Environment.owner_id == User.id).where(cond)
    rows = session.execute(q.order_by(Environment.id).offset(max(offset, 0)).limit(min(max(limit, 1), 1000)))
    count = session.scalar(select(func.count(Environment.id)).where(cond)) or 0
    return Page(data=[_public(e, owner) for e, owner in rows], count=count)


@router.get("/{name}", response_model=EnvironmentPublic)
def get_environment(name: str, session: SessionDep, user: CurrentUser) -> EnvironmentPublic:
    """One environment by name."""
    row = session.execute(
        select(Environment, User.name).outerjoin(User, Environment.owner_id == User.id)
        .where(Environment.name == name, visible(user))
    ).first()
    if row is None:
        raise HTTPException(404, "Environment not found")
    return _public(*row)


@router.post("", response_model=EnvironmentPublic, status_code=201)
def create_environment(body: EnvironmentCreate, session: SessionDep, user: CurrentUser) -> EnvironmentPublic:
    """Add an environment (validated like an environment file); names are unique."""
    try:
        env = parse_environment(body.to_data())
    except InvalidEnvironment as exc:
        raise HTTPException(422, str(exc)) from None
    if session.scalar(select(Environment).where(Environment.name == env.name)) is not None:
        raise HTTPException(409, f"Environment {env.name!r} already exists")
    row = Environment(name=env.name, owner_id=user.id, builtin=False, data=env.to_dict())
    session.add(row)
    session.commit()
    return _public(row, user.name)
