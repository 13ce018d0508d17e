"""Uploaded planner programs: upload (201), list, inspect, download; the sandbox's limits.

Programs are private: other users get 404 (admins see everyone's).  Uploads
are refused with 403 unless the server runs with ``--enable-uploads``
(``TWB_UPLOADS_ENABLED``).  How programs run: docs/uploads.md.
"""

from __future__ import annotations

import base64
import binascii
import hashlib

from fastapi import APIRouter, Query, Response
from sqlalchemy import func, select

from ...access import owned
from ...errors import Forbidden, Invalid, TooLarge
from ...models import Program
from ...schemas import Page, ProgramCreate, ProgramPublic, SandboxPublic
from ...submission import UPLOADS_DISABLED
from ..deps import MAX_OFFSET, CurrentUser, IdPath, SessionDep, TestbedDep
from ..responses import AUTHENTICATED, errors

router = APIRouter(prefix="/programs", tags=["programs"], responses=AUTHENTICATED)


@router.get("/sandbox", response_model=SandboxPublic)
async def sandbox_info(user: CurrentUser, testbed: TestbedDep) -> SandboxPublic:
    """Whether uploads are enabled, the interpreters, the limits and the isolation programs get here."""
    settings = testbed.settings
    return SandboxPublic(
        uploads_enabled=settings.uploads_enabled,
        interpreters=sorted(settings.sandbox_interpreters),
        limits=testbed.sandbox.limits,
        isolation=await testbed.sandbox.probe() if settings.uploads_enabled else None,
    )


@router.post("", response_model=ProgramPublic, status_code=201, responses=errors(413))
def upload_program(body: ProgramCreate, session: SessionDep, user: CurrentUser, testbed: TestbedDep) -> ProgramPublic:
    """Upload a planner program (base64); 403 if uploads are disabled, 413 if too large."""
    settings = testbed.settings
    if not settings.uploads_enabled:
        raise Forbidden(UPLOADS_DISABLED)
    limit = settings.max_program_bytes
    if len(body.content_base64) > (limit + 2) // 3 * 4 + 4:  # refuse before decoding
        raise TooLarge(f"program larger than {limit} bytes")
    try:
        content = base64.b64decode(body.content_base64, validate=True)
    except (binascii.Error, ValueError):
        raise Invalid("content_base64: not valid base64") from None
    if len(content) > limit:
        raise TooLarge(f"program larger than {limit} bytes")
    if not content:
        raise Invalid("content_base64: the program is empty")
    if body.kind == "executable" and body.interpreter is not None and body.interpreter not in settings.sandbox_interpreters:
        raise Invalid(f"interpreter {body.interpreter!r} is not available here; choose one of "
                                 f"{', '.join(sorted(settings.sandbox_interpreters))} or none (a binary or #! script)")
    if body.kind == "python" and "python3" not in settings.sandbox_interpreters:
        raise Invalid("this testbed has no python3 for programs; upload an executable")
    prog = Program(owner_id=user.id, name=body.name, kind=body.kind,
                   interpreter=body.interpreter if body.kind == "executable" else None, args=list(body.args),
                   content=content, size=len(content), sha256=hashlib.sha256(content).hexdigest(),
                   stochastic=body.stochastic)
    session.add(prog)
    session.commit()
    session.refresh(prog)
    return ProgramPublic.model_validate(prog)


@router.get("", response_model=Page[ProgramPublic])
def list_programs(
    session: SessionDep,
    user: CurrentUser,
    offset: int = Query(default=0, ge=0, le=MAX_OFFSET),
    limit: int = Query(default=50, ge=1, le=500),
) -> Page[ProgramPublic]:
    """Your programs, newest first (admins see everyone's)."""
    cond = [] if user.is_admin else [Program.owner_id == user.id]
    rows = session.scalars(select(Program).where(*cond).order_by(Program.id.desc()).offset(offset).limit(limit))
    count = session.scalar(select(func.count(Program.id)).where(*cond)) or 0
    return Page(data=[ProgramPublic.model_validate(p) for p in rows], count=count)


@router.get("/{program_id:int}", response_model=ProgramPublic, responses=errors(404))
def get_program(program_id: IdPath, session: SessionDep, user: CurrentUser) -> ProgramPublic:
    """One of your programs."""
    return ProgramPublic.model_validate(owned(session, user, Program, program_id, "Program"))


@router.get("/{program_id:int}/content", response_class=Response, responses={
    200: {"description": "The file's bytes.",
          "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}}},
    **errors(404)})
def get_program_content(program_id: IdPath, session: SessionDep, user: CurrentUser) -> Response:
    """The uploaded file itself."""
    prog = owned(session, user, Program, program_id, "Program")
    return Response(prog.content, media_type="application/octet-stream",
                     headers={"Content-Disposition": f'attachment; filename="{prog.name}"'})
