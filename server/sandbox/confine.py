"""What the program's process (or bwrap's, which becomes it) does between fork and exec: enter its cgroup,
become its user, take its limits."""

from __future__ import annotations

import os
import resource
import signal
from typing import Any, Callable, Optional

from .cgroups import ProgramCgroup
from .isolation import PR_SET_NO_NEW_PRIVS, PR_SET_PDEATHSIG, prctl

__all__ = ["confinement"]


def confinement(limits: dict[str, Any], *, cgroup: Optional[ProgramCgroup], uid: Optional[int],
                gid: Optional[int], nproc: Optional[int], file_bytes: int,
                seccomp: Optional[Any] = None) -> Callable[[], None]:
    """The ``preexec_fn`` (the launcher has no threads then, so it may run Python).

    In order: the cgroup (while still root: its files are root's), the
    ``uid``/``gid`` with no groups, the rlimits (``RLIMIT_AS`` only without a
    cgroup: then the memory limit is per process; ``RLIMIT_NPROC`` =
    ``nproc`` unless None: bwrap's sandbox gets it later, on its first
    process; ``RLIMIT_FSIZE`` = ``file_bytes``), ``no_new_privs``, the
    parent-death signal, default signal actions, and the seccomp filter
    ``seccomp`` (a ``pyseccomp`` filter; None: bwrap loads it, or none).
    """

    def apply() -> None:
        if cgroup is not None:
            cgroup.join()
        if uid is not None and gid is not None:
            os.setgroups([])
            os.setresgid(gid, gid, gid)
            os.setresuid(uid, uid, uid)

        def lim(res: int, soft: int, hard: Optional[int] = None) -> None:
            resource.setrlimit(res, (soft, soft if hard is None else hard))

        lim(resource.RLIMIT_CPU, int(limits["cpu_s"]), int(limits["cpu_s"]) + 1)
        if cgroup is None:
            lim(resource.RLIMIT_AS, int(limits["memory_bytes"]))
        lim(resource.RLIMIT_FSIZE, file_bytes)
        if nproc is not None:
            lim(resource.RLIMIT_NPROC, nproc)
        lim(resource.RLIMIT_NOFILE, int(limits["open_files"]))
        lim(resource.RLIMIT_CORE, 0)
        lim(resource.RLIMIT_MEMLOCK, 0)
        lim(resource.RLIMIT_MSGQUEUE, 0)
        if prctl(PR_SET_NO_NEW_PRIVS, 1) != 0:
            os._exit(126)
        prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        for s in (signal.SIGPIPE, signal.SIGXFSZ, signal.SIGXCPU):
            signal.signal(s, signal.SIG_DFL)
        if seccomp is not None:
            try:
                seccomp.load()
            except OSError:
                os._exit(126)

    return apply
