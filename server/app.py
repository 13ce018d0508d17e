"""The FastAPI application: routers, middleware, error bodies, and the testbed's life in its lifespan."""

from __future__ import annotations

import re
from contextlib import asynccontextmanager
from typing import AsyncIterator, Optional

from fastapi import FastAPI, HTTPException, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from sqlalchemy.exc import InterfaceError, OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException

from .api.deps import authenticate, bearer_token
from .api.middleware import BodyLimit, StopCancels
from .api.routes import (comparisons, controllers, dashboard, environments, events, experiments, field, health, meta,
                         planners, programs, runs, users)
from .core.settings import Settings
from .errors import RequestRefused
from .testbed import Testbed

__all__ = ["create_app"]

API_PREFIX = "/api/v1"


def create_app(settings: Optional[Settings] = None, testbed: Optional[Testbed] = None) -> FastAPI:
    """Build the API; the testbed is created (or the given one used) and started in the lifespan."""
    settings = settings or Settings()
    tb = testbed or Testbed(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        import anyio

        if not tb.admin_token:
            await anyio.to_thread.run_sync(tb.prepare)
        await tb.start()
        try:
            yield
        finally:
            await tb.stop()

    app = FastAPI(
        title="Teleworkbench emulator",
        version="1",
        summary="Remote robot testbed for benchmarking path planners (SI units: m, rad, s).",
        lifespan=lifespan,
    )
    app.state.testbed = tb

    @app.exception_handler(RequestRefused)
    async def _refused(request: Request, exc: RequestRefused) -> JSONResponse:
        return JSONResponse(status_code=exc.status_code, content={"detail": exc.detail}, headers=exc.headers)

    @app.exception_handler(OperationalError)
    @app.exception_handler(InterfaceError)
    async def _store_away(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse(status_code=503, content={"detail": "the database is unreachable; try again shortly"},
                            headers={"Retry-After": "5"})

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> Response:
        if exc.status_code == 400 and isinstance(exc.__cause__, ValueError):  # a body that is not UTF-8
            denied = await _token_first(request)
            return denied or JSONResponse(status_code=422, content={
                "detail": "body is not valid JSON (not UTF-8 text)",
                "errors": [{"loc": ["body"], "msg": "not UTF-8 text", "type": "json_invalid"}]})
        if exc.status_code == 405:
            return JSONResponse(status_code=405, content={"detail": exc.detail},
                                headers={"Allow": ", ".join(_allowed_methods(app, request.url.path))})
        return await http_exception_handler(request, exc)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> Response:
        errs = exc.errors()
        if any(e.get("type") == "json_invalid" for e in errs):
            denied = await _token_first(request)
            if denied is not None:
                return denied
        # one readable message first, the details after
        first = errs[0] if errs else {}
        if first.get("type") == "json_invalid":
            loc = first.get("loc", ())
            at = f" (at character {loc[-1]})" if loc and isinstance(loc[-1], int) else ""
            msg = f"body is not valid JSON: {(first.get('ctx') or {}).get('error', 'decode error')}{at}"
            return JSONResponse(status_code=422, content={"detail": msg, "errors": _jsonable(errs)})
        where = _where(first.get("loc", ()))
        # a validator's ValueError comes as "Value error, <its message>", and that message names the field itself
        text = str(first.get("msg", "invalid input")).removeprefix("Value error, ")
        msg = f"{where}: {text}" if where and not text.startswith(where) else text
        return JSONResponse(status_code=422, content={"detail": msg, "errors": _jsonable(errs)})

    app.include_router(health.router)
    app.include_router(dashboard.router)
    for module in (meta, users, environments, experiments, comparisons, runs, field, events, planners, controllers,
                   programs):
        app.include_router(module.router, prefix=API_PREFIX)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    app.add_middleware(StopCancels)  # outermost
    generate = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is None:
            _integer_bounds(generate())
        return app.openapi_schema  # type: ignore[return-value]

    app.openapi = openapi  # type: ignore[method-assign]
    return app


def _integer_bounds(node: object) -> None:
    """Integer schemas' bounds as JSON integers: FastAPI's OpenAPI models hold every bound as a float
    (``"maximum": 9.223372036854776e+18``), which a client's schema reads as another number.  Bounds are
    chosen to be exact as floats (``lt=2**63``, not ``le=2**63 - 1``)."""
    if isinstance(node, dict):
        kind = node.get("type")
        if kind == "integer" or (isinstance(kind, list) and "integer" in kind):
            for key in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
                value = node.get(key)
                if isinstance(value, float) and value.is_integer():
                    node[key] = int(value)
        for value in node.values():
            _integer_bounds(value)
    elif isinstance(node, list):
        for value in node:
            _integer_bounds(value)


async def _token_first(request: Request) -> Optional[JSONResponse]:
    """The 401/429 answer for a request without a valid token, else None.

    FastAPI parses a body before it resolves dependencies; a malformed body
    still gets the token checked first, so nobody without one learns
    anything from our answers.
    """
    try:
        await authenticate(request, bearer_token(request))
    except HTTPException as denied:
        return JSONResponse(status_code=denied.status_code, content={"detail": denied.detail}, headers=denied.headers)
    return None


def _allowed_methods(app: FastAPI, path: str) -> list[str]:
    """Every method the API serves on ``path`` (from its OpenAPI paths, integer parameters matching
    digits only), for a 405's ``Allow``."""
    methods: set[str] = set()
    for template, operations in app.openapi().get("paths", {}).items():
        for method, op in operations.items():
            if _template_regex(template, op.get("parameters", [])).fullmatch(path):
                methods.add(method.upper())
    return sorted(methods)


def _template_regex(template: str, parameters: list[dict]) -> re.Pattern[str]:
    """A regular expression for an OpenAPI path template (``/runs/{run_id}``) and its path parameters."""
    integer = {p["name"] for p in parameters if p.get("in") == "path" and p.get("schema", {}).get("type") == "integer"}
    parts = re.split(r"\{(\w+)\}", template)
    out = "".join(re.escape(part) if i % 2 == 0 else ("[0-9]+" if part in integer else "[^/]+")
                  for i, part in enumerate(parts))
    return re.compile(out)


def _where(loc: tuple) -> str:
    """A validation error's location as a reader writes it: ``blocks[0].w``, ``query.offset``."""
    out = ""
    for part in loc:
        if part == "body":
            continue
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _jsonable(errs: list) -> list:
    """Validation errors without the offending input (it may be huge, binary or NaN)."""
    return [{"loc": list(e.get("loc", ())), "msg": str(e.get("msg", "")), "type": str(e.get("type", ""))} for e in errs]
