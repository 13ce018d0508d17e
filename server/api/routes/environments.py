"""Environments (docs/design.md, "Environment file"): the built-ins and users' own."""

from __future__ import annotations

from fastapi import APIRouter, Query
from sqlalchemy import func, or_, select

from contract.frames import FIELD_SIZE, SUBFIELD_SIZE
from planners import InvalidEnvironment, parse_environment

from ...access import environment_named, visible_environments
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
        description=d.get("description", ""), moving_obstacles=d.get("moving_obstacles", []),
        moving_tracks=_tracks(d), builtin=row.builtin, owner=owner,
    )


def _tracks(d: dict) -> list[dict]:
    """The moving obstacles with their waypoints as they move (random walks expanded), for drawing."""
    if not d.get("moving_obstacles"):
        return []
    try:
        obstacles = parse_environment(d).moving_obstacles
    except InvalidEnvironment:  # stored before a rule tightened: shown without tracks, not an error
        return []
    return [{"radius": o.radius, "speed": o.speed, "repeat": o.repeat, "delay_s": o.delay_s,
             "waypoints": [list(p) for p in o.waypoints]} for o in obstacles]


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
    """One environment by name: yours, else the built-in one."""
    row = environment_named(session, user, name)
    if row is None:
        raise NotFound("Environment not found")
    return _public(row, session.get(User, row.owner_id).name if row.owner_id is not None else None)


@router.post("", response_model=EnvironmentPublic, status_code=201, responses=errors(409, 413))
def create_environment(body: EnvironmentCreate, session: SessionDep, user: CurrentUser) -> EnvironmentPublic:
    """Add an environment (validated like an environment file, at most the whole field); your names are
    unique, and built-in names are taken (409)."""
    try:
        env = parse_environment(body.to_data())
    except InvalidEnvironment as exc:
        raise Invalid(str(exc)) from None
    if env.width > FIELD_SIZE[0] + 1e-9 or env.height > FIELD_SIZE[1] + 1e-9:
        raise Invalid(f"size: the environment is {env.width:g} x {env.height:g} m; the field is "
                      f"{FIELD_SIZE[0]:g} x {FIELD_SIZE[1]:g} m (a sub-field {SUBFIELD_SIZE[0]:g} x "
                      f"{SUBFIELD_SIZE[1]:g} m)")
    taken = session.scalars(select(Environment).where(
        Environment.name == env.name, or_(Environment.builtin.is_(True), Environment.owner_id == user.id))).first()
    if taken is not None:
        raise Conflict(f"{env.name!r} is the name of a built-in environment" if taken.builtin
                       else f"you already have an environment named {env.name!r}")
    row = Environment(name=env.name, owner_id=user.id, builtin=False, data=env.to_dict())
    session.add(row)
    session.commit()
    return _public(row, user.name)
