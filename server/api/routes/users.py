"""Users and their tokens (admin only, except ``/users/me``)."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Query
from sqlalchemy import func, select

from ...core.security import hash_token, new_token
from ...errors import Conflict, NotFound
from ...models import Token, User
from ...schemas import Page, UserCreate, UserPublic, UserWithToken
from ..deps import MAX_OFFSET, AdminUser, CurrentUser, SessionDep, UserNamePath
from ..responses import AUTHENTICATED, errors

router = APIRouter(prefix="/users", tags=["users"], responses=AUTHENTICATED)


@router.get("/me", response_model=UserPublic)
def me(user: CurrentUser, session: SessionDep) -> UserPublic:
    """The user the token belongs to."""
    return UserPublic.model_validate(session.get(User, user.id))


@router.get("", response_model=Page[UserPublic])
def list_users(
    session: SessionDep,
    _: AdminUser,
    offset: int = Query(default=0, ge=0, le=MAX_OFFSET),
    limit: int = Query(default=100, ge=1, le=1000),
) -> Page[UserPublic]:
    """All users (admin only)."""
    rows = session.scalars(select(User).order_by(User.id).offset(offset).limit(limit))
    return Page(data=[UserPublic.model_validate(u) for u in rows], count=session.scalar(select(func.count(User.id))) or 0)


@router.post("", response_model=UserWithToken, status_code=201, responses=errors(409, 413))
def create_user(body: UserCreate, session: SessionDep, _: AdminUser) -> UserWithToken:
    """Create a user and return its bearer token, shown once (admin only)."""
    if session.scalar(select(User).where(User.name == body.name)) is not None:
        raise Conflict(f"User {body.name!r} already exists")
    user = User(name=body.name, is_admin=body.is_admin)
    token = new_token()
    session.add(user)
    session.flush()
    session.add(Token(user_id=user.id, token_hash=hash_token(token), kind="admin" if body.is_admin else "user"))
    session.commit()
    return UserWithToken(**UserPublic.model_validate(user).model_dump(), token=token)


@router.post("/{name}/tokens", response_model=UserWithToken, status_code=201, responses=errors(404))
def new_user_token(name: UserNamePath, session: SessionDep, _: AdminUser,
                   kind: Literal["user", "agent"] = Query(default="user")) -> UserWithToken:
    """Issue another token for a user; ``kind=agent`` makes a tracker/agent token (admin only)."""
    user = session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound("User not found")
    token = new_token()
    session.add(Token(user_id=user.id, token_hash=hash_token(token), kind=kind))
    session.commit()
    return UserWithToken(**UserPublic.model_validate(user).model_dump(), token=token)
