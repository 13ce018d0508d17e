"""The sandbox's processes: count them, kill them all by uid."""

from __future__ import annotations

import os
import signal
import time

__all__ = ["count_descendants", "count_uid", "kill_uid"]


def count_descendants(pid: int) -> int:
    """Processes below ``pid`` now (its children, theirs, ...; ``pid`` not counted); -1 if unknown.

    The sandbox's first process reaps every orphan of its pid namespace, so
    below it are exactly the program's processes.  Read from each thread's
    ``/proc/<pid>/task/<tid>/children``.
    """
    seen: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            if p == pid:
                return -1 if not os.path.isdir("/proc/self/task") else 0
            continue
        for tid in tasks:
            try:
                with open(f"/proc/{p}/task/{tid}/children") as f:
                    kids = [int(k) for k in f.read().split()]
            except (OSError, ValueError):
                continue
            for k in kids:
                if k not in seen:
                    seen.add(k)
                    todo.append(k)
    return len(seen)


def count_uid(uid: int, me: int) -> int:
    """Processes of the dedicated ``uid`` now (``me`` not counted); -1 if unknown."""
    try:
        entries = os.listdir("/proc")
    except OSError:
        return -1
    n = 0
    for e in entries:
        if not e.isdigit() or int(e) == me:
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
        if count_uid(uid, os.getpid()) <= 0:
            return
        time.sleep(0.01)
