"""Turning errors into one clear line on stderr and a non-zero exit, never a traceback."""

from __future__ import annotations

import os
import sys
from typing import NoReturn

__all__ = ["CliError", "fail", "report_exception"]


class CliError(Exception):
    """A user-facing command-line error; its message is printed as one line."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


def fail(message: str, code: int = 2) -> NoReturn:
    """Abort the command with ``message``."""
    raise CliError(message, code)


def report_exception(exc: BaseException) -> int:
    """Print ``exc`` as ``twb: error: ...`` and return the exit code to use.

    Expected errors (bad input, unreachable goals, missing files) print their
    message; anything else is an internal error, shown with a traceback only
    when ``TWB_DEBUG=1``.
    """
    from planners.errors import PlanningError

    if isinstance(exc, CliError):
        code, msg = exc.code, str(exc)
    elif isinstance(exc, (PlanningError, ValueError, OSError)):
        code, msg = 2, str(exc) or type(exc).__name__
    else:
        code, msg = 1, f"internal error: {type(exc).__name__}: {exc} (set TWB_DEBUG=1 for a traceback)"
    if os.environ.get("TWB_DEBUG") == "1":
        import traceback

        traceback.print_exception(exc)
    print(f"twb: error: {' '.join(msg.split())}", file=sys.stderr)
    return code
