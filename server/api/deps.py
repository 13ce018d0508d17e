"""FastAPI dependencies: database sessions, the current user, the running testbed."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Iterator

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy import select
from sqlalchemy.orm import Session

from ..core.security import hash_token
from ..models import Token, User

if TYPE_CHECKING:
    from ..testbed import Testbed

__all__ = ["AdminUser", "AgentToken", "CurrentUser", "SessionDep", "TestbedDep"]

_bearer = HTTPBearer(auto_error=False, description="`Authorization: Bearer <token>`")


def get_testbed(request: Request) -> "Testbed":
    return request.app.state.testbed


TestbedDep = Annotated["Testbed", Depends(get_testbed)]


def get_session(request: Request) -> Iterator[Session]:
    with request.app.state.testbed.sessions() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]


def _token(session: Session, creds: HTTPAuthorizationCredentials | None) -> Token:
    if creds is None or not creds.credentials:
        raise HTTPException(401, "Missing bearer token", headers={"WWW-Authenticate": "Bearer"})
    token = session.scalar(select(Token).where(Token.token_hash == hash_token(creds.credentials)))
    if token is None:
        raise HTTPException(401, "Invalid token", headers={"WWW-Authenticate": "Bearer"})
    return token


def get_current_user(
    session: SessionDep, creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> User:
    token = _token(session, creds)
    if token.kind == "agent":
        raise HTTPException(403, "Agent tokens may only post robot registrations and tracker poses")
    return token.user


CurrentUser = Annotated[User, Depends(get_current_user)]


def get_admin_user(user: CurrentUser) -> User:
    if not user.is_admin:
        raise HTTPException(403, "Admin only")
    return user


AdminUser = Annotated[User, Depends(get_admin_user)]


def get_agent_token(
    session: SessionDep, creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> Token:
    """Tracker ingestion and robot registration: an agent token or an admin's token."""
    token = _token(session, creds)
    if token.kind != "agent" and not token.user.is_admin:
        raise HTTPException(403, "Needs an agent (tracker) token")
    return token


AgentToken = Annotated[Token, Depends(get_agent_token)]
