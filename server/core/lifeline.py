"""Processes the server starts end with it: a watchdog thread that notices when the parent is gone.

Linux's parent-death signal follows the parent *thread* that forked, not the
process (a worker spawned from a short-lived thread would die too early), so
this polls ``getppid()`` instead: when the parent dies the process is
re-parented (to init or a sub-reaper) and the watchdog acts.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Callable, Optional

__all__ = ["exit_with_parent"]


def exit_with_parent(parent_pid: Optional[int] = None, *, interval_s: float = 0.5,
                     action: Optional[Callable[[], None]] = None) -> threading.Thread:
    """Start a daemon thread that calls ``action`` (default: ``os._exit(0)``) once ``parent_pid`` is gone.

    ``parent_pid`` defaults to the current parent; ``interval_s`` is how
    often (seconds) the thread looks.  Returns the started thread.
    """
    parent = os.getppid() if parent_pid is None else parent_pid
    act = action or (lambda: os._exit(0))

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(interval_s)
        act()

    thread = threading.Thread(target=watch, name="twb-lifeline", daemon=True)
    thread.start()
    return thread
