"""What planning may take in a worker: a memory limit for the process and a deadline per plan.

A worker of the testbed's compute pool runs other people's planning jobs one after the other: one job
asking for a grid of 2 mm cells, or a planner that never returns, must end as *that job's* failure, not
take the machine's memory or the worker.  :func:`configure_worker` caps the worker's data segment
(``RLIMIT_DATA``: heap and anonymous mappings, numpy's arrays among them), so an allocation beyond it is a
``MemoryError`` in the job; :func:`planning_limits` turns that, and a plan that runs past the deadline
(``SIGALRM``, delivered between Python bytecodes: a long compiled loop is interrupted when it returns to
Python), into a :class:`PlanningLimit` — a :class:`planners.PlanningError`, so the run fails ``planning``
with the reason.  Units: MiB, seconds.
"""

from __future__ import annotations

import resource
import signal
import threading
from contextlib import contextmanager
from typing import Iterator

from planners import PlanningError

__all__ = ["PlanningLimit", "configure_worker", "limits", "planning_limits"]

_limits = {"memory_mb": 0, "deadline_s": 0.0}


class PlanningLimit(PlanningError):
    """A plan ran out of the worker's memory or past its deadline: the job's own doing."""


def configure_worker(memory_mb: int, deadline_s: float) -> None:
    """In a fresh worker process: cap its data segment at ``memory_mb`` MiB (0: no cap) and give every plan
    ``deadline_s`` seconds of wall time (0: none)."""
    if memory_mb > 0:
        size = int(memory_mb) << 20
        _soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
        resource.setrlimit(resource.RLIMIT_DATA, (size, size if hard == resource.RLIM_INFINITY else min(size, hard)))
    _limits.update(memory_mb=int(memory_mb), deadline_s=float(deadline_s))


def limits() -> dict[str, float]:
    """This process's planning limits: ``memory_mb`` (0: none) and ``deadline_s`` (0: none)."""
    return dict(_limits)


@contextmanager
def planning_limits() -> Iterator[None]:
    """Run a plan under this worker's limits; their breach raises :class:`PlanningLimit` naming it."""
    deadline = _limits["deadline_s"]
    armed = deadline > 0 and threading.current_thread() is threading.main_thread()
    if armed:
        def expire(signum: int, frame: object) -> None:
            raise PlanningLimit(f"the planning time limit of {deadline:g} s was reached (the testbed's "
                                "planning_timeout_s)")

        previous = signal.signal(signal.SIGALRM, expire)
        signal.setitimer(signal.ITIMER_REAL, deadline)
    try:
        yield
    except MemoryError as exc:
        raise PlanningLimit(f"the planning memory limit of {_limits['memory_mb']} MiB per worker was reached "
                            f"({exc or 'an allocation failed'}): choose coarser planner parameters") from None
    finally:
        if armed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
