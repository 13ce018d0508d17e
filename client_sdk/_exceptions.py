"""Exceptions of the SDK: one tree, so ``except TwbError`` catches everything it raises.

::

    TwbError
    ├── ApiError(status, detail)        the server answered with an error status
    │   ├── Unauthorized                401: no token or an unknown token
    │   ├── Forbidden                   403: the token may not do this (e.g. admin only)
    │   ├── NotFound                    404: unknown id, or not yours
    │   ├── Conflict                    409: wrong state (e.g. cancelling a finished experiment)
    │   ├── TooLarge                    413: request body too large
    │   ├── ValidationError             422: invalid input; ``detail`` is the server's reason
    │   ├── RateLimited                 429: too many queued experiments, or unknown tokens
    │   └── Unavailable                 503: the testbed cannot serve for the moment
    ├── TransportError                  the server (or a robot agent) could not be reached
    ├── RobotError                      a robot agent answered something that is not protocol v1
    └── WaitTimeout                     also a ``TimeoutError``: ``wait()`` ran out of time

Errors of the HTTP library are translated in one place
(:func:`client_sdk._base.translate_errors`) with ``raise ... from exc``, so the
original exception stays available as ``__cause__``.  An :class:`ApiError`
carries ``retry_after``: the seconds the server's ``Retry-After`` asked to
wait (None without one); the clients wait that long and ask again themselves
before a 429 or 503 becomes an error (``docs/sdk.md``, "Retries").
"""

from __future__ import annotations

from typing import Any, Optional

__all__ = [
    "ApiError",
    "Conflict",
    "Forbidden",
    "NotFound",
    "RateLimited",
    "RobotError",
    "TooLarge",
    "TransportError",
    "TwbError",
    "Unauthorized",
    "Unavailable",
    "ValidationError",
    "WaitTimeout",
]


class TwbError(Exception):
    """Base class of every error the SDK raises."""


class ApiError(TwbError):
    """The server answered ``status`` (>= 400); ``detail`` is its ``{"detail": ...}`` message.

    ``str(err)`` is one line: ``"404 Not Found: Experiment not found"``, then the
    ``hint`` (what to do about it) when there is one.  ``retry_after``: the
    seconds the server's ``Retry-After`` header asked to wait, or None.
    """

    def __init__(self, status: int, detail: Any, *, method: str = "", url: str = "", hint: str = "",
                 retry_after: Optional[float] = None) -> None:
        self.status = status
        self.detail = detail
        self.method = method
        self.url = url
        self.hint = hint
        self.retry_after = retry_after
        text = f"{status} {_REASONS.get(status, 'Error')}: {format_detail(detail)}"
        super().__init__(f"{text} ({hint})" if hint else text)


class Unauthorized(ApiError):
    """401: the request had no token or an unknown one; without a token ``hint`` says where the SDK
    looked for one and how to pass one."""


class Forbidden(ApiError):
    """403: the token is valid but may not do this."""


class NotFound(ApiError):
    """404: unknown id or name, or it belongs to another user."""


class Conflict(ApiError):
    """409: the resource is in the wrong state (or the name is taken)."""


class TooLarge(ApiError):
    """413: the request body is too large."""


class ValidationError(ApiError):
    """422: the server refused the input; ``detail`` tells why."""


class RateLimited(ApiError):
    """429: too many queued experiments, or too many unknown tokens from this client (``retry_after`` s)."""


class Unavailable(ApiError):
    """503: the testbed cannot serve for the moment, e.g. its database is unreachable (``retry_after`` s)."""


class TransportError(TwbError):
    """No answer: connection refused, DNS failure, timeout, connection reset."""


class RobotError(TwbError):
    """A robot agent sent a line that is not protocol v1 (e.g. no ``HELLO`` greeting)."""


class WaitTimeout(TwbError, TimeoutError):
    """``wait()`` gave up: the experiment had not finished in time (it keeps running)."""

    def __init__(self, message: str, experiment: Any = None) -> None:
        super().__init__(message)
        self.experiment = experiment


_REASONS = {
    400: "Bad Request",
    401: "Unauthorized",
    403: "Forbidden",
    404: "Not Found",
    405: "Method Not Allowed",
    409: "Conflict",
    413: "Payload Too Large",
    422: "Unprocessable Entity",
    429: "Too Many Requests",
    500: "Internal Server Error",
    501: "Not Implemented",
    502: "Bad Gateway",
    503: "Service Unavailable",
}

#: status code -> exception class; other codes raise a plain :class:`ApiError`
STATUS_ERRORS: dict[int, type[ApiError]] = {
    401: Unauthorized,
    403: Forbidden,
    404: NotFound,
    409: Conflict,
    413: TooLarge,
    422: ValidationError,
    429: RateLimited,
    503: Unavailable,
}


def format_detail(detail: Any) -> str:
    """One line from a ``detail``: a string as is, FastAPI's validation list as ``loc: msg; ...``."""
    if isinstance(detail, list):
        parts = []
        for item in detail:
            if isinstance(item, dict):
                loc = ".".join(str(p) for p in item.get("loc", ()) if p != "body")
                msg = str(item.get("msg", item))
                parts.append(f"{loc}: {msg}" if loc else msg)
            else:
                parts.append(str(item))
        text = "; ".join(parts)
    else:
        text = str(detail)
    return " ".join(text.split())
