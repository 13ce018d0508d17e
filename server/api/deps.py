"""FastAPI dependencies: the running testbed, database sessions, who is asking."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Iterator

import anyio
from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from ..core.security import Principal

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


async def _principal(request: Request, creds: HTTPAuthorizationCredentials | None) -> Principal:
    if creds is None or not creds.credentials:
        raise HTTPException(401, "Missing bearer token", headers={"WWW-Authenticate": "Bearer"})
    auth = request.app.state.testbed.auth
    who = auth.cached(creds.credentials)
    if who is None:
        who = await anyio.to_thread.run_sync(auth.load, creds.credentials)
    if who is None:
        raise HTTPException(401, "Invalid token", headers={"WWW-Authenticate": "Bearer"})
    return who


async def get_current_user(
    request: Request, creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> Principal:
    who = await _principal(request, creds)
    if who.kind == "agent":
        raise HTTPException(403, "Agent tokens may only post robot registrations and tracker poses")
    return who


CurrentUser = Annotated[Principal, Depends(get_current_user)]


def get_admin_user(user: CurrentUser) -> Principal:
    if not user.is_admin:
        raise HTTPException(403, "Admin only")
    return user


AdminUser = Annotated[Principal, Depends(get_admin_user)]


async def get_agent_token(
    request: Request, creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> Principal:
    """Tracker ingestion and robot registration: an agent token or an admin's token."""
    who = await _principal(request, creds)
    if who.kind != "agent" and not who.is_admin:
        raise HTTPException(403, "Needs an agent (tracker) token")
    return who


AgentToken = Annotated[Principal, Depends(get_agent_token)]
