"""When the launcher ends early: the server asks (SIGTERM) or is gone (the parent-death signal).

The parent-death signal (``PR_SET_PDEATHSIG``) follows the parent *thread*:
it also comes when the server thread that started the launcher exits while
the server lives on.  So it is SIGHUP, handled by comparing ``getppid()``
with the parent at start (the real parent's death changes it, a thread's
does not), and the supervision loop compares ``getppid()`` on every turn as
well.
"""

from __future__ import annotations

import os
import signal
from typing import Callable, Optional

from .isolation import PR_SET_PDEATHSIG, prctl

__all__ = ["PARENT_DEATH_SIGNAL", "EndRequest"]

PARENT_DEATH_SIGNAL = signal.SIGHUP


class EndRequest:
    """Why this process should end early (``reason``), and what to do at once when it should (``on_end``)."""

    def __init__(self) -> None:
        self.reason: Optional[str] = None
        self.on_end: Optional[Callable[[], None]] = None
        self._parent = os.getppid()

    def listen(self, *, watch_parent: bool) -> None:
        """Handle SIGTERM; with ``watch_parent`` also the death of the parent process (the server)."""
        signal.signal(signal.SIGTERM, lambda *_: self._end("stopped by the server"))
        if watch_parent:
            signal.signal(PARENT_DEATH_SIGNAL, lambda *_: self.check())
            prctl(PR_SET_PDEATHSIG, PARENT_DEATH_SIGNAL)
            self.check()  # the parent may have died before the signal was set
        else:
            signal.signal(PARENT_DEATH_SIGNAL, signal.SIG_DFL)

    def check(self) -> Optional[str]:
        """The reason to end, if any; looks at the parent now."""
        if self.reason is None and os.getppid() != self._parent:
            self._end("the server is gone")
        return self.reason

    def _end(self, reason: str) -> None:
        if self.reason is None:
            self.reason = reason
        if self.on_end is not None:
            self.on_end()
