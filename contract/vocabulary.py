"""The run vocabulary: modes, run statuses, why a run failed, and how a run ended (its outcome).

One definition for the server, the SDK, the study tooling and the tests; the dashboard
reads the same lists from ``GET /api/v1/meta``.  What each status means — whose fault
it is — is in docs/design.md, "Run states".  These are ``StrEnum``\\s: they compare
equal to, hash as, store as and serialise as their plain string values, so
``"completed" in TERMINAL`` and ``run["mode"] == Mode.TWB`` hold for plain strings too.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Optional

__all__ = ["ACTIVE", "JOB_OUTCOMES", "JUDGED", "NOT_COUNTED", "SUCCESS", "TERMINAL", "FailureKind", "Mode", "RunStatus",
           "run_outcome", "vocabulary"]


class Mode(StrEnum):
    """Where a run drives: an idealised simulation or the (emulated) physical field."""

    SIM = "sim"  # perfect actuation, exact poses (Player/Stage-like)
    TWB = "twb"  # the Teleworkbench field: tracker noise and latency, motor lag, collisions stop the robot


class RunStatus(StrEnum):
    """Where a run (or, rolled up, an experiment) stands."""

    QUEUED = "queued"
    BUILDING = "building"
    PLACING = "placing"
    PLANNING = "planning"
    RUNNING = "running"
    ANALYZING = "analyzing"
    COMPLETED = "completed"
    FAILED = "failed"  # the job's own fault: no path, collision, stall, timeout
    ERROR = "error"  # the testbed's fault: robot unreachable, died, refused; retried once
    CANCELLED = "cancelled"  # the owner's wish
    INTERRUPTED = "interrupted"  # the testbed stopped during the run


class FailureKind(StrEnum):
    """Why a run ``failed`` (the job's own fault)."""

    PLANNING = "planning"  # the planner found no path (or gave an unusable one)
    PROGRAM = "program"  # the uploaded program gave no usable path
    COLLISION = "collision"  # the robot hit an obstacle (its own verdict: EV,FAIL,COLLISION)
    TIMEOUT = "timeout"  # the run took longer than the testbed's run timeout
    CONTROLLER_TIMEOUT = "controller_timeout"  # the robot's controller gave up (EV,FAIL,TIMEOUT)
    STALLED = "stalled"  # the robot made no progress (EV,FAIL,STALLED)
    OTHER = "other"  # a failure reason this server does not know


#: the states of a run under way, in the order a run passes them
ACTIVE: tuple[RunStatus, ...] = (RunStatus.BUILDING, RunStatus.PLACING, RunStatus.PLANNING, RunStatus.RUNNING,
                                 RunStatus.ANALYZING)
#: the states a run ends in
TERMINAL: frozenset[RunStatus] = frozenset({RunStatus.COMPLETED, RunStatus.FAILED, RunStatus.ERROR,
                                            RunStatus.CANCELLED, RunStatus.INTERRUPTED})
#: the endings that are the job's own (completed or failed): success rates and metrics count these runs;
#: a testbed error, a cancel or an interruption says nothing about the planner
JUDGED: frozenset[RunStatus] = frozenset({RunStatus.COMPLETED, RunStatus.FAILED})

#: the outcome of a completed run
SUCCESS = "success"
#: the outcomes of the runs in :data:`JUDGED`: success, each failure kind, and ``failed`` (a failed run that
#: stored no kind)
JOB_OUTCOMES: tuple[str, ...] = (SUCCESS, *(k.value for k in FailureKind), RunStatus.FAILED.value)
#: the outcomes of runs a success rate does not count (the testbed's fault, the owner's wish, not ended)
NOT_COUNTED: tuple[str, ...] = (RunStatus.ERROR.value, RunStatus.CANCELLED.value, RunStatus.INTERRUPTED.value,
                                "pending")


def run_outcome(status: Optional[str], failure: Optional[str] = None) -> str:
    """How a run ended: ``success`` (completed), why a failed run failed (a :class:`FailureKind` value, or
    ``failed`` when it stored none), its status for the other endings (``error``, ``cancelled``,
    ``interrupted``), and ``pending`` while it has not ended.  The one outcome rule of the project."""
    if status == RunStatus.COMPLETED:
        return SUCCESS
    if status == RunStatus.FAILED:
        return failure or RunStatus.FAILED.value
    return str(status) if status in TERMINAL else "pending"


def vocabulary() -> dict[str, list[str]]:
    """The vocabulary as plain lists, for clients that cannot import this module (the dashboard)."""
    return {"modes": [m.value for m in Mode], "statuses": [s.value for s in RunStatus],
            "active": [s.value for s in ACTIVE], "terminal": [s.value for s in RunStatus if s in TERMINAL],
            "judged": [s.value for s in RunStatus if s in JUDGED], "failure_kinds": [k.value for k in FailureKind],
            "job_outcomes": list(JOB_OUTCOMES), "not_counted": list(NOT_COUNTED)}
