"""The testbed's state vocabulary: how an experiment's status rolls up, sub-field and robot states.

A run moves ``queued → building → placing → planning → running → analyzing``
and ends in one of the terminal statuses (:mod:`contract.vocabulary`, re-exported
here); an experiment's status rolls up from its runs (:func:`roll_up`).  What
each terminal status means — whose fault it is — is in docs/design.md ("Run
states").  These are ``StrEnum``\\s: they compare equal to, store as and
serialise as their plain string values.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Iterable

from contract.vocabulary import ACTIVE, TERMINAL, RunStatus

__all__ = ["ACTIVE", "TERMINAL", "RobotStatus", "RunStatus", "SubfieldState", "roll_up"]


#: which terminal status an experiment takes when its runs ended differently (the first one any run has)
_ROLL_UP_ORDER = (RunStatus.CANCELLED, RunStatus.ERROR, RunStatus.FAILED, RunStatus.INTERRUPTED)


def roll_up(statuses: Iterable[str]) -> RunStatus:
    """An experiment's status from its runs' statuses.

    Unfinished: ``queued`` until a run starts, then the state of the most
    advanced active run (``running`` while some runs ended and the rest wait).
    Finished: ``cancelled`` > ``error`` > ``failed`` > ``interrupted`` >
    ``completed`` (the first that any run has).
    """
    sts = [RunStatus(s) for s in statuses]
    if not sts:
        return RunStatus.QUEUED
    if all(s in TERMINAL for s in sts):
        return next((s for s in _ROLL_UP_ORDER if s in sts), RunStatus.COMPLETED)
    active = [s for s in sts if s in ACTIVE]
    if active:
        return max(active, key=ACTIVE.index)
    return RunStatus.RUNNING if any(s in TERMINAL for s in sts) else RunStatus.QUEUED


class SubfieldState(StrEnum):
    """What a sub-field is doing (``GET /api/v1/subfields``)."""

    IDLE = "idle"
    RESERVED = "reserved"  # assigned to a run that has not started building
    BUILDING = "building"  # the gripper builds the environment
    RUNNING = "running"
    OFFLINE = "offline"  # no robot registered on it


class RobotStatus(StrEnum):
    """How a registered robot is (``GET /api/v1/robots``)."""

    IDLE = "idle"
    BUSY = "busy"
    OFFLINE = "offline"  # it failed a run or is known from an earlier start; probed until it answers
