"""The FastAPI application: routers, middleware, error bodies, and the testbed's life in its lifespan."""

from __future__ import annotations

from contextlib import asynccontextmanager
from typing import AsyncIterator, Optional

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from .api.middleware import BodyLimit
from .api.routes import dashboard, environments, events, experiments, field, health, planners, programs, runs, users
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

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        # one readable message first, the details after
        errs = exc.errors()
        first = errs[0] if errs else {}
        where = ".".join(str(p) for p in first.get("loc", ()) if p != "body")
        msg = f"{where}: {first.get('msg', 'invalid input')}" if where else first.get("msg", "invalid input")
        return JSONResponse(status_code=422, content={"detail": msg, "errors": _jsonable(errs)})

    app.include_router(health.router)
    app.include_router(dashboard.router)
    for module in (users, environments, experiments, runs, field, events, planners, programs):
        app.include_router(module.router, prefix=API_PREFIX)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    return app


def _jsonable(errs: list) -> list:
    """Validation errors without the offending input (it may be huge, binary or NaN)."""
    return [{"loc": list(e.get("loc", ())), "msg": str(e.get("msg", "")), "type": str(e.get("type", ""))} for e in errs]
