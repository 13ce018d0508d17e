"""The few kernel interfaces the launcher calls itself: ``prctl``, capabilities, entering a network namespace.

Namespaces, mounts and capabilities of the program are bubblewrap's
(:mod:`.bwrap`); what is left here runs in the launcher or in its short-lived
helper processes.  Linux only.
"""

from __future__ import annotations

import ctypes
import fcntl
import os

__all__ = ["CAP_SETGID", "CAP_SETUID", "PR_SET_CHILD_SUBREAPER", "PR_SET_NO_NEW_PRIVS", "PR_SET_PDEATHSIG",
           "enter_network_namespace", "has_cap", "prctl"]

CLONE_NEWUSER = 0x10000000
CLONE_NEWNET = 0x40000000
#: ioctl on a namespace's file: a file of the user namespace that owns it
NS_GET_USERNS = 0xB701

PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36
PR_SET_NO_NEW_PRIVS = 38

CAP_SETGID, CAP_SETUID = 6, 7

libc = ctypes.CDLL(None, use_errno=True)
libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
libc.setns.argtypes = [ctypes.c_int, ctypes.c_int]


def prctl(option: int, arg: int) -> int:
    """``prctl(option, arg)``; 0 on success, -1 on failure (errno in ``ctypes.get_errno()``)."""
    return libc.prctl(option, arg, 0, 0, 0)


def has_cap(cap: int) -> bool:
    """Whether this process has capability ``cap`` in its effective set."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> cap & 1)
    return False


def _setns(fd: int, kind: int, what: str) -> None:
    if libc.setns(fd, kind) != 0:
        e = ctypes.get_errno()
        raise OSError(e, f"setns {what}: {os.strerror(e)}")


def enter_network_namespace(pid: int) -> None:
    """Move this (single-threaded, throw-away) process into the network namespace of ``pid``.

    Root may enter it at once; the server's own user (not root) first joins
    the user namespace that owns it (bubblewrap made it as that user, who thus
    has the capabilities in it) — asked of the network namespace itself
    (``NS_GET_USERNS``): ``pid`` may since have moved on into a nested user
    namespace.  Irreversible for the user namespace: call it in a child that
    exits afterwards.
    """
    net = os.open(f"/proc/{pid}/ns/net", os.O_RDONLY | os.O_CLOEXEC)
    try:
        try:
            _setns(net, CLONE_NEWNET, "net")
            return
        except PermissionError:
            pass
        user = fcntl.ioctl(net, NS_GET_USERNS)
        try:
            _setns(user, CLONE_NEWUSER, "user")
        finally:
            os.close(user)
        _setns(net, CLONE_NEWNET, "net")
    finally:
        os.close(net)
