"""Start-up of the store: migrations, built-in environments, the admin, sub-fields, recovery.

Runs once per server start, before the scheduler: nothing here touches robots.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from planners import builtin_names, load_environment

from .core.security import hash_token, new_token
from .core.settings import Settings
from .models import Environment, Token, User
from .store.field import reset_subfields
from .store.runs import interrupt_active, requeue_interrupted

__all__ = ["bootstrap_store"]

log = logging.getLogger("twb.server")


def _admin_token(settings: Settings) -> str:
    if settings.admin_token:
        return settings.admin_token
    path = settings.token_file
    if path.exists():
        text = path.read_text().strip()
        if text:
            return text
    return new_token()


def _write_token(path: Path, token: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")


def bootstrap_store(settings: Settings, sessions: sessionmaker[Session]) -> str:
    """Prepare the database; returns the admin token (also written to ``data_dir/token``)."""
    token = _admin_token(settings)
    with sessions.begin() as s:
        for name in builtin_names():
            data = load_environment(name).to_dict()
            row = s.scalar(select(Environment).where(Environment.name == name, Environment.builtin.is_(True)))
            if row is None:
                s.add(Environment(name=name, builtin=True, data=data))
            elif row.builtin:
                row.data = data
        admin = s.scalar(select(User).where(User.name == "admin"))
        if admin is None:
            admin = User(name="admin", is_admin=True)
            s.add(admin)
            s.flush()
        if s.scalar(select(Token).where(Token.token_hash == hash_token(token))) is None:
            s.add(Token(user_id=admin.id, token_hash=hash_token(token), kind="admin", label="twb up"))
        reset_subfields(s)
        # runs cut by a server stop: the robots did not finish them under our watch
        cut = interrupt_active(s, "the server stopped while this run was in progress")
        if cut:
            log.warning("marked %d run(s) interrupted by the last server stop", cut)
        if settings.resume_interrupted:
            resumed = requeue_interrupted(s)
            if resumed:
                log.warning("queued %d interrupted run(s) again", resumed)
    _write_token(settings.token_file, token)
    return token
