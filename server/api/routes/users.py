"""Users and their tokens (admin only, except ``/users/me``)."""

from __future__ import annotations

from fastapi import APIRouter
from sqlalchemy import func, select

from ...core.security import hash_token, new_token
from ...errors import Conflict, Invalid, NotFound
from ...models import Token, User
from ...schemas import Page, UserCreate, UserPublic, UserWithToken
from ..deps import AdminUser, CurrentUser, SessionDep

router = APIRouter(prefix="/users", tags=["users"])


@router.get("/me", response_model=UserPublic)
def me(user: CurrentUser, session: SessionDep) -> UserPublic:
    """The user the token belongs to."""
    return UserPublic.model_validate(session.get(User, user.id))


@router.get("", response_model=Page[UserPublic])
def list_users(session: SessionDep, _: AdminUser, offset: int = 0, limit: int = 100) -> Page[UserPublic]:
    """All users (admin only)."""
    rows = session.scalars(select(User).order_by(User.id).offset(max(offset, 0)).limit(min(max(limit, 1), 1000)))
    return Page(data=[UserPublic.model_validate(u) for u in rows], count=session.scalar(select(func.count(User.id))) or 0)


@router.post("", response_model=UserWithToken, status_code=201)
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


@router.post("/{name}/tokens", response_model=UserWithToken, status_code=201)
def new_user_token(name: str, session: SessionDep, _: AdminUser, kind: str = "user") -> UserWithToken:
    """Issue another token for a user; ``kind=agent`` makes a tracker/agent token (admin only)."""
    user = session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound("User not found")
    if kind not in ("user", "agent"):
        raise Invalid("kind must be 'user' or 'agent'")
    token = new_token()
    session.add(Token(user_id=user.id, token_hash=hash_token(token), kind=kind))
    session.commit()
    return UserWithToken(**UserPublic.model_validate(user).model_dump(), token=token)
