"""The FastAPI application factory and its lifespan (migrations, scheduler)."""

from __future__ import annotations

from contextlib import asynccontextmanager
from typing import AsyncIterator, Optional

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from .api.routes import dashboard, environments, events, experiments, field, health, planners, programs, runs, users
from .core.settings import Settings
from .testbed import Testbed

__all__ = ["create_app"]

API_PREFIX = "/api/v1"


class BodyLimit:
    """ASGI middleware: refuse request bodies larger than ``limit`` bytes with 413, streamed or not.

    A declared ``Content-Length`` over the limit is refused before reading; a
    chunked body is cut off at the limit (the application sees an empty end
    of body) and whatever it answers is replaced by the 413.
    """

    def __init__(self, app, limit: int) -> None:  # type: ignore[no-untyped-def]
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):  # type: ignore[no-untyped-def]
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        for name, value in scope.get("headers", []):
            if name == b"content-length" and value.isdigit() and int(value) > self.limit:
                return await _too_large(send, self.limit)
        seen, over, answered = 0, False, False

        async def limited_receive():  # type: ignore[no-untyped-def]
            nonlocal seen, over
            if over:
                return {"type": "http.request", "body": b"", "more_body": False}
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    over = True
                    return {"type": "http.request", "body": b"", "more_body": False}
            return message

        async def guarded_send(message):  # type: ignore[no-untyped-def]
            nonlocal answered
            if not over:
                return await send(message)
            if not answered:
                answered = True
                await _too_large(send, self.limit)

        await self.app(scope, limited_receive, guarded_send)
        if over and not answered:
            await _too_large(send, self.limit)


async def _too_large(send, limit: int) -> None:  # type: ignore[no-untyped-def]
    body = ('{"detail": "Request body larger than %d bytes"}' % limit).encode()
    await send({"type": "http.response.start", "status": 413,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})


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
