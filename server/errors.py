"""Every error the server raises on purpose, in one tree::

    TestbedError
    ├── RequestRefused          an API request cannot be served; answered with its HTTP status
    │   ├── Forbidden           403
    │   ├── NotFound            404 (also for other users' rows: they cannot learn that it exists)
    │   ├── Conflict            409
    │   ├── TooLarge            413
    │   ├── Invalid             422
    │   │   └── PreflightError  a job that cannot run (server.validation)
    │   ├── QuotaExceeded       429
    │   └── NotInstalled        501 (an optional package the request needs is missing)
    └── RunEnded                a run stopped short of ``completed``; the class says whose fault it is
        ├── RunFailed           ``failed``: the job's own fault, of a :class:`FailureKind`
        │   └── ProgramFailed   the uploaded program gave no usable path
        └── TestbedFault        ``error``: the testbed's fault; the run is retried once on another robot
            ├── AgentUnavailable    the robot agent cannot be reached, closed or went silent
            └── AgentRefused        the robot agent answered ``ERR`` to a command

The API turns a :class:`RequestRefused` into ``{"detail": ...}`` with its
status (``server.app``); the run pipeline turns a :class:`RunEnded` into the
run's status and error text (``server.pipeline.runner``).
"""

from __future__ import annotations

from typing import Any, Optional

from contract.vocabulary import FailureKind

from .status import RunStatus

__all__ = [
    "AgentRefused",
    "AgentUnavailable",
    "Conflict",
    "EngineFault",
    "FailureKind",
    "Forbidden",
    "Invalid",
    "NotFound",
    "NotInstalled",
    "PreflightError",
    "ProgramFailed",
    "QuotaExceeded",
    "RequestRefused",
    "RunEnded",
    "RunFailed",
    "TestbedError",
    "TestbedFault",
    "TooLarge",
]


class TestbedError(Exception):
    """Base of the server's own errors."""

    __test__ = False  # not a test class, whatever pytest thinks of the name


# --------------------------------------------------------------------------- API requests


class RequestRefused(TestbedError):
    """A request the API refuses; ``status_code`` is its HTTP status, the message its ``detail``."""

    status_code = 400

    def __init__(self, detail: str, *, headers: Optional[dict[str, str]] = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.headers = headers


class Forbidden(RequestRefused):
    status_code = 403


class NotFound(RequestRefused):
    status_code = 404


class Conflict(RequestRefused):
    status_code = 409


class TooLarge(RequestRefused):
    status_code = 413


class Invalid(RequestRefused):
    status_code = 422


class PreflightError(Invalid):
    """The job cannot run; the message says why."""


class QuotaExceeded(RequestRefused):
    status_code = 429


class NotInstalled(RequestRefused):
    """The server lacks an optional package (an extra of the project) the request needs; the message names
    the command that installs it."""

    status_code = 501


# --------------------------------------------------------------------------- run outcomes


class RunEnded(TestbedError):
    """A run stopped short of ``completed``; ``status`` is the run's status."""

    status: RunStatus = RunStatus.ERROR


class RunFailed(RunEnded):
    """The job's own fault: the run ends ``failed`` with this message.

    ``whole_experiment``: the path could not be had (planning, program), so
    the experiment's other runs fail too instead of trying again.
    """

    status = RunStatus.FAILED

    def __init__(self, message: str, kind: FailureKind = FailureKind.OTHER, *, whole_experiment: bool = False) -> None:
        super().__init__(message)
        self.kind = kind
        self.whole_experiment = whole_experiment
        #: the moving obstacle (its index in the environment) of a collision with one, else None
        self.obstacle: int | None = None


class ProgramFailed(RunFailed):
    """The uploaded program gave no usable path; ``info`` is what is known of its execution."""

    def __init__(self, message: str, info: Optional[dict[str, Any]] = None) -> None:
        super().__init__(message, FailureKind.PROGRAM, whole_experiment=True)
        self.info = info or {}


class TestbedFault(RunEnded):
    """The testbed's fault: the run ends ``error`` (and is retried once on another robot)."""

    status = RunStatus.ERROR


class AgentUnavailable(TestbedFault):
    """The robot agent cannot be reached, closed the connection or stopped answering."""


class AgentUnreachable(AgentUnavailable):
    """The robot agent could not be connected to: nothing was sent, the run did not begin on it."""


class AgentRefused(TestbedFault):
    """The robot agent answered ``ERR,<code>,<message>``."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"{code}: {message}")
        self.code, self.message = code, message


class EngineFault(TestbedFault):
    """The compute engine (Ray) lost a task: a worker or node died, the cluster went away.  The run ends
    ``error`` and is retried once, as after a dead agent; no robot is blamed."""
