"""The sandbox's processes: count them, kill them all by uid."""

from __future__ import annotations

import os
import signal
import time
from typing import Optional

__all__ = ["count_processes", "kill_uid"]


def count_processes(*, pid_namespace: bool, uid: Optional[int], me: int) -> int:
    """Processes of the sandbox now, ``me`` not counted; -1 if unknown.

    ``pid_namespace``: this process sees only the sandbox's (its own pid
    namespace and /proc); else those of the dedicated ``uid`` count.
    """
    if not pid_namespace and uid is None:
        return -1
    try:
        entries = os.listdir("/proc")
    except OSError:
        return -1
    n = 0
    for e in entries:
        if not e.isdigit() or int(e) == me:
            continue
        if pid_namespace:
            n += 1
            continue
        try:
            if os.stat(f"/proc/{e}").st_uid == uid:
                n += 1
        except OSError:
            pass
    return n


def kill_uid(uid: int) -> None:
    """Kill every process of the dedicated ``uid``: ``kill(-1)`` from a helper running as that uid."""
    for _ in range(20):
        pid = os.fork()
        if pid == 0:  # pragma: no cover - child
            try:
                os.setgroups([])
                os.setresgid(uid, uid, uid)
                os.setresuid(uid, uid, uid)
                os.kill(-1, signal.SIGKILL)
            except OSError:
                pass
            os._exit(0)
        os.waitpid(pid, 0)
        if count_processes(pid_namespace=False, uid=uid, me=os.getpid()) <= 0:
            return
        time.sleep(0.01)
