"""The API's error body and which error statuses each operation documents (OpenAPI ``responses``).

Every error is ``{"detail": "<one readable sentence>"}``; a 422 from request
validation adds ``errors``, every problem found with where it is.
"""

from __future__ import annotations

from typing import Any, Optional, Union

from pydantic import BaseModel, Field

__all__ = ["AUTHENTICATED", "EXPORTED", "ErrorBody", "errors"]


class Issue(BaseModel):
    """One problem with a request: where it is (``["body", "start", 0]``), what, and its kind."""

    loc: list[Union[str, int]]
    msg: str
    type: str


class ErrorBody(BaseModel):
    """Why a request was refused."""

    detail: str = Field(description="What went wrong, in one readable sentence.")
    errors: Optional[list[Issue]] = Field(default=None, description="422 from validation: every problem found.")


_WHY = {
    401: "No bearer token, or not a valid one.",
    403: "The token may not do this (an agent token, a user where an admin is needed, uploads disabled).",
    404: "Unknown, or not yours.",
    409: "The resource is in a state that does not allow this (or the name is taken).",
    413: "The request body (or an uploaded program) is larger than allowed.",
    422: "Invalid input: the reason first, then every problem found.",
    429: "Too many: over a quota, or too many failed tokens from this client (see Retry-After).",
    501: "The server lacks an optional package this needs; the message names the command that installs it.",
    503: "The database is unreachable for the moment (see Retry-After).",
}


def errors(*codes: int) -> dict[Union[int, str], dict[str, Any]]:
    """OpenAPI ``responses`` entries for the given error statuses, all with :class:`ErrorBody`."""
    return {code: {"model": ErrorBody, "description": _WHY[code]} for code in codes}


#: what any operation that needs a token can answer
AUTHENTICATED = errors(401, 403, 422, 429, 503)


#: the success answer of an export: an MCAP file or a zipped ROS 2 bag (docs/exports.md)
EXPORTED: dict[Union[int, str], dict[str, Any]] = {200: {
    "description": "The export as a download: an MCAP file (`format=mcap`) or a ROS 2 bag directory, zipped "
                   "(`format=rosbag2`).",
    "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}},
                "application/zip": {"schema": {"type": "string", "format": "binary"}}}}}
