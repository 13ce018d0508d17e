"""Users and their tokens as stored (tokens only as SHA-256 hashes)."""

from __future__ import annotations

from typing import Optional

from sqlalchemy import select
from sqlalchemy.orm import Session

from ..core.security import Principal
from ..models import Token, User

__all__ = ["principal_of"]


def principal_of(session: Session, token_hash: str) -> Optional[Principal]:
    """Who holds the token with this hash (None: no such token)."""
    row = session.execute(select(Token.kind, User.id, User.name, User.is_admin, Token.id).join(User)
                           .where(Token.token_hash == token_hash)).first()
    return None if row is None else Principal(id=row[1], name=row[2], is_admin=row[3], kind=row[0], token_id=row[4],
                                              token_hash=token_hash)
