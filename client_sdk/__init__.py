"""Python SDK of the Teleworkbench emulator: REST clients, typed results, raw TCP sender.

>>> from client_sdk import Client
>>> with Client() as twb:                       # doctest: +SKIP
...     exp = twb.submit("room", start=[0.3, 0.3, 0.0], goal=[1.5, 1.5, 1.5708], planner="fm2")
...     exp = twb.wait(exp.id, timeout=300, progress=True)
...     poses = twb.get_poses(exp.runs[0].id)          # (N, 4): t, x, y, theta

``Client`` and ``AsyncClient`` share one core (``BaseClient``: URLs, auth,
parsing; no I/O).  The URL comes from the argument, ``$TWB_URL`` or
``http://127.0.0.1:8000``; the token from the argument, ``$TWB_TOKEN`` or the
file ``twb up`` writes (``$TWB_DATA_DIR/token``, default ``./twb-data/token``).
Every error is a :class:`TwbError` (tree in :mod:`client_sdk._exceptions`).
This package imports no server code; see ``docs/sdk.md``.
"""

from ._base import BaseClient
from ._client import AsyncClient, Client
from ._config import DEFAULT_URL, resolve_token, resolve_url, token_file
from ._exceptions import (
    ApiError,
    Conflict,
    Forbidden,
    NotFound,
    RateLimited,
    RobotError,
    TooLarge,
    TransportError,
    TwbError,
    Unauthorized,
    Unavailable,
    ValidationError,
    WaitTimeout,
)
from ._models import (
    TERMINAL_STATES,
    CancelResult,
    ComparedExperiment,
    ComparisonReport,
    ComparisonRow,
    ConfigurationOutcome,
    DirectComparison,
    Environment,
    Experiment,
    ExperimentMetrics,
    ExperimentSummary,
    Message,
    ModeAggregate,
    ObstacleTracks,
    Outcomes,
    Page,
    Plan,
    Program,
    Robot,
    Run,
    RunMetrics,
    Subfield,
    Summary,
    User,
)
from ._tcp import PathReply, path_with_headings, send_path

__all__ = sorted(
    [
        "ApiError",
        "AsyncClient",
        "BaseClient",
        "CancelResult",
        "Client",
        "ComparedExperiment",
        "ComparisonReport",
        "ComparisonRow",
        "ConfigurationOutcome",
        "Conflict",
        "DEFAULT_URL",
        "DirectComparison",
        "Environment",
        "Experiment",
        "ExperimentMetrics",
        "ExperimentSummary",
        "Forbidden",
        "Message",
        "ModeAggregate",
        "ObstacleTracks",
        "Outcomes",
        "NotFound",
        "Page",
        "PathReply",
        "Plan",
        "Program",
        "RateLimited",
        "Robot",
        "RobotError",
        "Run",
        "RunMetrics",
        "Subfield",
        "Summary",
        "User",
        "TERMINAL_STATES",
        "TooLarge",
        "TransportError",
        "TwbError",
        "Unauthorized",
        "Unavailable",
        "ValidationError",
        "WaitTimeout",
        "path_with_headings",
        "resolve_token",
        "resolve_url",
        "send_path",
        "token_file",
    ]
)
