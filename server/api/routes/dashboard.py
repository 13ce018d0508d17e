"""The web dashboard: ``/`` serves the page, ``/static/...`` its files (plain JS modules, CSS; no build step).

The files live in ``server/static`` (package data).  They are served by plain
routes rather than a mounted ``StaticFiles`` app so that ``include_router``
carries them on every FastAPI version.  The page itself needs no token; every
API call it makes sends ``Authorization: Bearer`` (the live event stream
included: it is read with ``fetch`` streaming, not ``EventSource``).
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse


__all__ = ["STATIC_DIR", "router"]

STATIC_DIR = Path(__file__).resolve().parents[2] / "static"

router = APIRouter(tags=["dashboard"])

_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".json": "application/json",
    ".txt": "text/plain; charset=utf-8",
}

#: the token lives in web storage, so no script, style or connection from anywhere else
_CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
        "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
_HEADERS = {
    "Cache-Control": "no-cache",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": _CSP,
}


def _file(path: Path) -> FileResponse:
    return FileResponse(path, media_type=_TYPES.get(path.suffix, "application/octet-stream"), headers=_HEADERS)


@router.api_route("/", methods=["GET", "HEAD"], include_in_schema=False)
def dashboard() -> FileResponse:
    """The dashboard page."""
    return _file(STATIC_DIR / "index.html")


@router.api_route("/static/{path:path}", methods=["GET", "HEAD"], include_in_schema=False)
def static_file(path: str) -> FileResponse:
    """A file of the dashboard (never outside ``server/static``)."""
    target = (STATIC_DIR / path).resolve()
    if not target.is_relative_to(STATIC_DIR) or not target.is_file() or target.suffix not in _TYPES:
        raise HTTPException(404, "Not found")
    return _file(target)
