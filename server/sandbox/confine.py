"""What the program's process does between fork and exec: enter its cgroup, become its user, take its limits."""

from __future__ import annotations

import os
import resource
import signal
from typing import Any, Callable, Optional

from .cgroups import ProgramCgroup
from .isolation import PR_CAPBSET_DROP, PR_SET_NO_NEW_PRIVS, PR_SET_PDEATHSIG, prctl
from .seccomp import install_seccomp

__all__ = ["confinement"]


def confinement(limits: dict[str, Any], *, cgroup: Optional[ProgramCgroup], uid: Optional[int],
                gid: Optional[int], drop_caps: bool, nproc_extra: int,
                seccomp: Optional[bytes]) -> Callable[[], None]:
    """The ``preexec_fn`` of the program (the launcher has no threads then, so it may run Python).

    In order: the cgroup (while still root: its files are root's), the
    ``uid``/``gid`` with no groups, the rlimits (``RLIMIT_AS`` only without a
    cgroup: then the memory limit is per process), no capabilities after exec
    (``drop_caps``: root of a user namespace), ``no_new_privs``, the
    parent-death signal, default signal actions, seccomp.  ``nproc_extra``:
    processes of the same user that are not the program's — in a user
    namespace the launcher's two processes count against its limit.
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
        lim(resource.RLIMIT_FSIZE, int(limits["file_bytes"]))
        lim(resource.RLIMIT_NPROC, int(limits["processes"]) + nproc_extra)
        lim(resource.RLIMIT_NOFILE, int(limits["open_files"]))
        lim(resource.RLIMIT_CORE, 0)
        lim(resource.RLIMIT_MEMLOCK, 0)
        lim(resource.RLIMIT_MSGQUEUE, 0)
        if drop_caps:
            for cap in range(64):
                if prctl(PR_CAPBSET_DROP, cap) != 0:
                    break
        if prctl(PR_SET_NO_NEW_PRIVS, 1) != 0:
            os._exit(126)
        prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        for s in (signal.SIGPIPE, signal.SIGXFSZ, signal.SIGXCPU):
            signal.signal(s, signal.SIG_DFL)
        if seccomp is not None and install_seccomp(seccomp) != 0:
            os._exit(126)

    return apply
