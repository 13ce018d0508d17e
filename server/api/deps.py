"""FastAPI dependencies: the running testbed, database sessions, who is asking."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Iterator, Optional

import anyio
from fastapi import Depends, HTTPException, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from ..core.security import Principal

if TYPE_CHECKING:
    from ..testbed import Testbed

__all__ = ["MAX_OFFSET", "AdminUser", "AgentToken", "CurrentUser", "IdPath", "NamePath", "SessionDep", "TestbedDep",
           "UserNamePath", "authenticate", "bearer_token"]

#: row ids are 64-bit; larger numbers are refused (422), never passed to the database
IdPath = Annotated[int, Path(ge=1, lt=2**63, description="Row id.")]  # lt: exact in OpenAPI (float bounds)
NamePath = Annotated[str, Path(min_length=1, max_length=100)]
UserNamePath = Annotated[str, Path(min_length=1, max_length=64)]
#: the largest list offset (rows); far beyond any store, and safe for every database
MAX_OFFSET = 2**31 - 1


_bearer = HTTPBearer(auto_error=False, description="`Authorization: Bearer <token>`")


def get_testbed(request: Request) -> "Testbed":
    return request.app.state.testbed


TestbedDep = Annotated["Testbed", Depends(get_testbed)]


def get_session(request: Request) -> Iterator[Session]:
    with request.app.state.testbed.sessions() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]


async def authenticate(request: Request, token: Optional[str]) -> Principal:
    """Who holds ``token``: 401 when missing or unknown, 429 after too many unknown ones from this client."""
    if not token:
        raise HTTPException(401, "Missing bearer token", headers={"WWW-Authenticate": "Bearer"})
    testbed = request.app.state.testbed
    who = testbed.auth.cached(token)
    if who is not None:
        return who
    client = request.client.host if request.client else "unknown"
    wait = testbed.failed_tokens.wait_s(client)
    if wait > 0:
        raise HTTPException(429, f"Too many unknown tokens from {client}; try again in {math.ceil(wait)} s",
                            headers={"Retry-After": str(math.ceil(wait))})
    who = await anyio.to_thread.run_sync(testbed.auth.load, token)
    if who is None:
        testbed.failed_tokens.failed(client)
        raise HTTPException(401, "Invalid token", headers={"WWW-Authenticate": "Bearer"})
    return who


def bearer_token(request: Request) -> Optional[str]:
    """The request's bearer token, if it has one."""
    scheme, _, token = request.headers.get("authorization", "").partition(" ")
    return token.strip() or None if scheme.lower() == "bearer" else None


async def _principal(request: Request, creds: HTTPAuthorizationCredentials | None) -> Principal:
    return await authenticate(request, creds.credentials if creds else None)


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
